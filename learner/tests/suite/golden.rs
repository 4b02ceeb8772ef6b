//! The comparison experiment at a tiny size (2 seeds × 10 iterations, LQR+GAIfO and GAIfO (PPO) at 5 episodes per iteration, demos
//! from the default expert) against a copy of its CSV committed before the learner was split
//! into crates (`tests/data/golden/comparison_2x10.csv`). Wall-clock columns (`t_*_s`,
//! `cpu_learner_s`) are left out; every other field must match: numbers bit for bit, text
//! exactly.
//!
//! A change that alters results on purpose regenerates the copy in the same commit and says why
//! in the commit message: `GOLDEN_REGENERATE=1 cargo test --release -p learner --test suite golden::`.

use std::path::{Path, PathBuf};

use learner::experiment::{run, ExperimentConfig, ExperimentName};

fn golden_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/golden/comparison_2x10.csv")
}

/// The CSV with the wall-clock columns removed, one string per line (header included).
fn without_times(text: &str) -> Vec<String> {
    let header: Vec<&str> = text.lines().next().expect("a header").split(',').collect();
    let keep: Vec<usize> = (0..header.len())
        .filter(|&i| !(header[i].starts_with("t_") || header[i].starts_with("cpu_")))
        .collect();
    text.lines()
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            assert_eq!(f.len(), header.len(), "row {l}");
            keep.iter().map(|&i| f[i]).collect::<Vec<_>>().join(",")
        })
        .collect()
}

#[test]
fn comparison_2_seeds_10_iterations_matches_the_committed_csv() {
    let mut cfg = ExperimentConfig::defaults(ExperimentName::Comparison);
    cfg.seeds = 2;
    cfg.iterations = 10;
    cfg.threads = 2;
    // The paper's two curves; the converged-budget PPO variant is not part of the copy.
    cfg.algorithms = vec!["lqr-gaifo".into(), "gaifo-ppo".into()];
    let out = std::env::temp_dir().join(format!("learner-golden-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    run(ExperimentName::Comparison, &cfg, &out, None).expect("the experiment runs");
    let got = std::fs::read_to_string(out.join("comparison.csv")).expect("comparison.csv");
    let _ = std::fs::remove_dir_all(&out);
    let path = golden_path();
    if std::env::var_os("GOLDEN_REGENERATE").is_some() {
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(&path, without_times(&got).join("\n") + "\n").unwrap();
        eprintln!("wrote {}", path.display());
        return;
    }
    let want = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("{}: {e} (regenerate: see module docs)", path.display()));
    let (got, want): (Vec<String>, Vec<String>) = (
        without_times(&got),
        want.lines().map(String::from).collect(),
    );
    assert_eq!(got.len(), want.len(), "number of CSV lines");
    // Numbers are compared by value, bit for bit (NaN with NaN), so that only a change of the
    // printed format (e.g. `1` vs `1.0`) is not a difference; every other field as text.
    let same = |g: &str, w: &str| match (g.parse::<f64>(), w.parse::<f64>()) {
        (Ok(a), Ok(b)) => a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
        _ => g == w,
    };
    for (k, (g, w)) in got.iter().zip(&want).enumerate() {
        let (gf, wf): (Vec<&str>, Vec<&str>) = (g.split(',').collect(), w.split(',').collect());
        assert!(
            gf.len() == wf.len() && gf.iter().zip(&wf).all(|(a, b)| same(a, b)),
            "CSV line {} differs from the committed copy:\n got  {g}\n want {w}",
            k + 1
        );
    }
}
