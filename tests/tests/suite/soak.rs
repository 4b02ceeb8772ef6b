//! The soak's checks (`integration_tests::soak`, `src/bin/soak.rs`): the scan counts exactly
//! the corrupted files, mixed-version episodes and commands outside the limits planted in a run
//! folder; a short soak (12 s, a kill every 2–4 s) ends with none of them. Assertions are on
//! invariants only (what the processes manage in 12 s depends on the machine's load).

use std::path::Path;

use imitation::rollout::Episode;
use integration_tests::reaching_table;
use integration_tests::soak::{scan_run, CYCLE};
use learner::io::episode::{save_episode, EpisodeOrigin};
use learner::io::table::save_table;
use ur5_shared::config::{ActionMode, ArmLimits, TaskConfig};
use ur5_shared::noise::Noise;
use ur5_shared::safety::clamp_action;
use ur5_shared::{controller_action, GainTable, DU, DX};

const T: usize = 30;
const DT: f64 = 0.1;
const SEED: u64 = 4;

/// An episode of `table` from the task's start pose on a first-order arm that reaches its
/// command (states made up; the scan checks only actions against states): noise-free, or with
/// the noise of episode `k` of `version`.
fn episode(table: &GainTable, version: u64, k: Option<u64>) -> Episode {
    let task = TaskConfig::default();
    let mut noise = k.map(|k| Noise::new(SEED, version, k));
    let mut q = task.start_arm_joints();
    let (mut x, mut u, mut u_policy, mut eps) = (vec![], vec![], vec![], vec![]);
    for t in 0..T {
        let mut s = [0.0; DX];
        s[..3].copy_from_slice(&q);
        let e = noise.as_mut().map_or([0.0; DU], |n| n.next());
        let mut a = [0.0; DU];
        controller_action(table, t, &s, &e, &mut a).unwrap();
        u_policy.extend(a);
        clamp_action(
            ActionMode::GoalAngles,
            &ArmLimits::default(),
            DT,
            &q,
            &mut a,
        );
        x.extend(s);
        u.extend(a);
        eps.extend(e);
        q = a;
    }
    Episode {
        layout: ur5_shared::StateLayout::REACH3,
        x,
        u,
        u_policy,
        eps,
        noisy: k.is_some(),
    }
}

fn save(dir: &Path, name: &str, ep: &Episode, version: u64) {
    let origin = EpisodeOrigin {
        table_version: version,
        table_epoch: 0,
        episode: 0,
        seed: SEED,
    };
    let task = TaskConfig {
        horizon: T,
        ..TaskConfig::default()
    };
    save_episode(&dir.join("episodes").join(name), ep, &origin, &task).unwrap();
}

#[test]
fn the_scan_counts_exactly_the_planted_defects() {
    let dir = integration_tests::scratch("soak-scan");
    std::fs::create_dir_all(dir.join("episodes")).unwrap();
    std::fs::create_dir_all(dir.join("tables")).unwrap();
    let v1 = reaching_table(1, T, [0.3, -1.6, 2.0], 0.05);
    let v2 = reaching_table(2, T, [0.1, -1.2, 1.5], 0.05);
    save_table(&dir.join("tables/v0001.npz"), &v1, DT).unwrap();
    save_table(&dir.join("tables/v0002.npz"), &v2, DT).unwrap();

    // Good: noise-free and noisy episodes of one version each (k found by the search).
    save(&dir, "000001_e000000_v0001.npz", &episode(&v1, 1, None), 1);
    save(
        &dir,
        "000002_e000001_v0001.npz",
        &episode(&v1, 1, Some(3)),
        1,
    );
    save(
        &dir,
        "000003_e000002_v0002.npz",
        &episode(&v2, 2, Some(0)),
        2,
    );
    // Mixed: the second half executed by version 2, recorded as version 1.
    let (a, b) = (episode(&v1, 1, None), episode(&v2, 2, None));
    let mut mixed = a.clone();
    mixed.u_policy[T / 2 * DU..].copy_from_slice(&b.u_policy[T / 2 * DU..]);
    save(&dir, "000004_e000003_v0001.npz", &mixed, 1);
    // Mixed: the name says version 2, the file version 1.
    save(&dir, "000005_e000004_v0002.npz", &a, 1);
    // Noise of an episode index the controller cannot reach in one cycle pattern: a noisy
    // episode at an index that is noise-free (k % 6 == 5) is not explained either.
    assert_eq!(CYCLE, (5, 1));
    save(
        &dir,
        "000006_e000005_v0001.npz",
        &episode(&v1, 1, Some(5)),
        1,
    );
    // Outside the limits: one executed action moved 1 rad in one step (the law is intact).
    let mut fast = episode(&v1, 1, None);
    fast.u[4 * DU + 1] += 1.0;
    save(&dir, "000007_e000006_v0001.npz", &fast, 1);
    // Corrupted: an episode cut short, a table cut short, a JSON file cut, a CSV
    // with its last row cut.
    let good = std::fs::read(dir.join("episodes/000001_e000000_v0001.npz")).unwrap();
    std::fs::write(
        dir.join("episodes/000008_e000007_v0001.npz"),
        &good[..good.len() / 2],
    )
    .unwrap();
    let table = std::fs::read(dir.join("tables/v0002.npz")).unwrap();
    std::fs::write(dir.join("latest_table.npz"), &table[..table.len() - 30]).unwrap();
    std::fs::write(dir.join("run.json"), "{\"command\": \"serve\", \"se").unwrap();
    std::fs::write(dir.join("serve_log.csv"), "a,b,c\n1,2,3\n4,5,3\n6,7").unwrap();
    // A temporary of an atomic write: counted apart.
    std::fs::write(dir.join("episodes/000009_e000008_v0001.npz.tmp"), b"half").unwrap();

    let scan = scan_run(&dir);
    assert_eq!(scan.episode_files, 8, "{scan:#?}");
    assert_eq!(scan.table_files, 2);
    assert_eq!(scan.max_version, 2);
    assert_eq!(scan.mixed_versions, 3, "{scan:#?}");
    assert_eq!(scan.outside_limits, 1, "{scan:#?}");
    assert_eq!(scan.corrupted, 4, "{scan:#?}");
    assert_eq!(scan.csv_rows, 3);
    assert_eq!(scan.temporaries, 1);
    assert_eq!(scan.files, 14);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_short_soak_finds_no_mixed_version_no_corrupted_file_and_no_command_outside_the_limits() {
    let dir = integration_tests::scratch("soak-smoke");
    let out = dir.join("soak");
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_soak"))
        .args([
            "--minutes",
            "0.2",
            "--seed",
            "3",
            "--kill-every-s",
            "2",
            "--json",
            "--out",
        ])
        .arg(&out)
        .output()
        .expect("run soak");
    let stdout = String::from_utf8_lossy(&run.stdout);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "soak failed:\n{stdout}\n{stderr}");
    let j = integration_tests::json_summary(&stdout, &stderr);
    for key in [
        "mixed_versions",
        "corrupted_files",
        "commands_outside_limits",
        "hangs",
    ] {
        assert_eq!(j[key], 0, "{key}: {j}");
    }
    assert_eq!(
        j["never_recovered"].as_array().map(Vec::len),
        Some(0),
        "{j}"
    );
    // Counts consistent: the files are what the scan read; a recorded episode was completed
    // by a controller (one killed between its last sample and its report line adds at most one).
    let n = |k: &str| j[k].as_u64().unwrap_or_else(|| panic!("{k} in {j}"));
    assert_eq!(
        n("episodes_recorded"),
        j["scan"]["episode_files"].as_u64().unwrap()
    );
    let ctl_kills = j["controller"]["kills"].as_u64().unwrap();
    assert!(
        n("episodes_recorded") <= n("episodes_completed") + ctl_kills,
        "more recorded than completed: {j}"
    );
    let kills: u64 = ["sim", "controller", "learner"]
        .iter()
        .map(|p| j[p]["kills"].as_u64().unwrap())
        .sum();
    assert!(kills <= 6, "at most one kill every 2 s in 12 s: {j}");
    std::fs::remove_dir_all(&dir).ok();
}
