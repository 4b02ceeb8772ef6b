//! Recorded runs through the `learner` binary: a run of `learner train
//! --record-episodes` (LQR+GAIfO, GAIfO (PPO)) replays equal bit for bit (`learner replay`,
//! docs/design.md §4.13), a
//! changed episode or a changed table entry is reported at the iteration where it shows, and
//! the run exports as an MCAP file that the `mcap` crate's reader reads back (§4.14).

use crate::common;

use std::path::{Path, PathBuf};

use common::{learner, learner_output, save_short_demos};
use learner::io::episode::{load_episode, load_episode_task, save_episode};
use learner::io::table::{load_stored, save_table};

const ITERATIONS: usize = 3;

fn scratch(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("replay-{tag}-{}", std::process::id()));
    std::fs::remove_dir_all(&d).ok();
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A recorded `learner train` run of ITERATIONS iterations in `dir/run` on short demonstrations.
fn recorded_run(dir: &Path) -> PathBuf {
    recorded_run_of(dir, "lqr-gaifo")
}

/// `learner train --algo ALGO --record-episodes` of `ITERATIONS` iterations on short demos in
/// `dir`; returns the run folder.
fn recorded_run_of(dir: &Path, algo: &str) -> PathBuf {
    let demos = dir.join("d.npz");
    save_short_demos(&demos, 0);
    let run = dir.join("run");
    let (ok, err) = learner(&[
        "train",
        "--algo",
        algo,
        "--demos",
        demos.to_str().unwrap(),
        "--iterations",
        &ITERATIONS.to_string(),
        "--record-episodes",
        "--out",
        run.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    run
}

/// `learner replay RUN --json`: (success, report, stderr).
fn replay(run: &Path) -> (bool, serde_json::Value, String) {
    let (ok, out, err) = learner_output(&["replay", run.to_str().unwrap(), "--json"]);
    let report = serde_json::from_str(out.trim()).unwrap_or_else(|e| panic!("{e}: {out}\n{err}"));
    (ok, report, err)
}

/// The recorded episode files of `run` whose name ends with `_vVERSION.npz`, in arrival order.
fn episodes_of(run: &Path, version: u64) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(run.join("episodes"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| {
            p.to_str()
                .unwrap()
                .ends_with(&format!("_v{version:04}.npz"))
        })
        .collect();
    files.sort();
    files
}

/// Records `path` as the run's own file in the run's record of its files, as the run does when
/// it writes one: an edit made so is the replay's comparison to find.
fn rerecord(run: &Path, path: &Path) {
    learner::io::files::note(run, &[path]).unwrap();
}

/// Makes `run` look like a run of a build without the record of its files.
fn forget_record(run: &Path) {
    std::fs::remove_file(run.join(learner::io::files::FILES)).unwrap();
    let manifest = run.join("run.json");
    let mut m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&manifest).unwrap()).unwrap();
    m.as_object_mut().unwrap().remove("files");
    std::fs::write(&manifest, serde_json::to_vec(&m).unwrap()).unwrap();
}

/// Adds `by` to state value `i` (flat index into the (T, dX) states) of the noisy episode
/// recorded in `path`.
fn nudge(path: &Path, i: usize, by: f64) {
    let (mut ep, origin) = load_episode(path).unwrap();
    let task = load_episode_task(path).unwrap();
    assert!(ep.noisy);
    ep.x[i] += by;
    save_episode(path, &ep, &origin, &task).unwrap();
}

#[test]
fn a_recorded_run_replays_bit_for_bit() {
    let dir = scratch("equal");
    let run = recorded_run(&dir);
    // N = 5 noisy + 1 noise-free per iteration, all recorded.
    let n = std::fs::read_dir(run.join("episodes")).unwrap().count();
    assert_eq!(n, ITERATIONS * 6);
    let (ok, r, err) = replay(&run);
    assert!(ok, "{err}");
    assert!(r["difference"].is_null(), "{r}");
    assert_eq!(r["iterations"], ITERATIONS as u64, "{r}");
    assert_eq!(r["episodes_used"], (ITERATIONS * 6) as u64, "{r}");
    // iter_000 … iter_003: the initial table and one per iteration, with their critics.
    assert_eq!(r["tables_checked"], ITERATIONS as u64 + 1, "{r}");
    assert_eq!(r["critics_checked"], ITERATIONS as u64 + 1, "{r}");
    assert!(err.contains("equal"), "{err}");

    // A run resumed from another folder (`learner serve --resume OTHER --out RUN`, as its
    // episodes/learned.jsonl says) cannot be replayed from RUN alone: said, not a vague error.
    let list = run.join("episodes").join(learner::io::learned::LEARNED);
    let from = learner::io::files::len(&list);
    learner::io::learned::append_event(
        &run.join("episodes"),
        &learner::io::learned::LearnedEvent::Resumed {
            iteration: 2,
            same_folder: false,
        },
    )
    .unwrap();
    learner::io::files::note_appended(&run, &list, from).unwrap();
    let (ok, err) = learner(&["replay", run.to_str().unwrap()]);
    assert!(!ok);
    assert!(
        err.contains("resumed from another folder after 2 iterations"),
        "{err}"
    );

    // Recorded episodes deleted: named as missing.
    std::fs::remove_dir_all(run.join("episodes")).unwrap();
    let (ok, err) = learner(&["replay", run.to_str().unwrap()]);
    assert!(!ok);
    assert!(
        err.contains(
            "19 of the run's files are not as its record files.jsonl says: \
                      episodes/000001_e000000_v0001.npz missing"
        ),
        "{err}"
    );
    // Without recorded episodes (and no record saying there were) there is nothing to
    // replay, and the message says how to get them.
    forget_record(&run);
    let (ok, err) = learner(&["replay", run.to_str().unwrap()]);
    assert!(!ok);
    assert!(err.contains("--record-episodes"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_changed_episode_or_table_entry_is_the_first_difference() {
    let dir = scratch("tamper");
    let run = recorded_run(&dir);

    // One state value of the first noisy episode of version 2: the tables of versions 1 and
    // 2 still equal, the update of iteration 2 learns another table (version 3).
    let path = episodes_of(&run, 2)[0].clone();
    nudge(&path, 5 * 12 + 6, 1e-9);
    // Against the run's record of its files, the edit is found before any learning.
    let (ok, err) = learner(&["replay", run.to_str().unwrap()]);
    assert!(!ok);
    let name = path.file_name().unwrap().to_str().unwrap();
    assert!(
        err.contains(&format!("episodes/{name} altered (bytes 0..")),
        "{err}"
    );
    // As the run's own file, it is the comparison's to find.
    rerecord(&run, &path);
    let (ok, r, err) = replay(&run);
    assert!(!ok, "a difference exits non-zero");
    let d = &r["difference"];
    assert_eq!(d["iteration"], 2, "{r}");
    assert_eq!(d["version"], 3, "{r}");
    assert!(
        d["file"].as_str().unwrap().ends_with("iter_002_table.npz"),
        "{r}"
    );
    assert_ne!(d["recorded"], d["replayed"], "{r}");
    assert!(
        d["episodes"]
            .as_array()
            .unwrap()
            .iter()
            .any(|p| p.as_str() == path.to_str()),
        "the changed episode is among those learned from: {r}"
    );
    assert!(err.contains("first difference at iteration 2"), "{err}");

    // Undo it; change one entry of the table of iteration 1 instead (as stored: the file's
    // checksum is left as it was).
    nudge(&path, 5 * 12 + 6, -1e-9);
    rerecord(&run, &path);
    assert!(replay(&run).0, "restored");
    let table_file = run.join("iter_001_table.npz");
    let (mut table, dt) =
        learner::io::table::load_table(&table_file, &ur5_shared::GainBounds::default()).unwrap();
    let was = table.step(4).k_vec[1];
    table.step_mut(4).k_vec[1] = was + 0.5;
    save_table(&table_file, &table, dt).unwrap();
    rerecord(&run, &table_file);
    assert_eq!(
        load_stored(&table_file).unwrap().arrays[1].2[4 * 3 + 1],
        was + 0.5
    );
    let (ok, r, _) = replay(&run);
    assert!(!ok);
    let d = &r["difference"];
    assert_eq!(d["iteration"], 1, "{r}");
    assert_eq!(d["array"], "k", "{r}");
    assert_eq!(d["index"], serde_json::json!([4, 1]), "{r}");
    assert!(
        d["recorded"]
            .as_str()
            .unwrap()
            .starts_with(&format!("{:?} ", was + 0.5)),
        "{r}"
    );
    assert!(
        d["replayed"]
            .as_str()
            .unwrap()
            .starts_with(&format!("{was:?} ")),
        "{r}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// GAIfO (PPO), `learner train --algo gaifo-ppo --record-episodes`: the replay redoes the
/// critic and PPO updates from the recorded episodes and compares every `iter_NNN_policy.json`
/// and `iter_NNN_critic.json` byte for byte; a changed episode shows at the update that
/// learned from it, in the policy file, at a byte offset.
#[test]
fn a_recorded_gaifo_ppo_run_replays_bit_for_bit() {
    let dir = scratch("ppo");
    let run = recorded_run_of(&dir, "gaifo-ppo");
    assert_eq!(
        std::fs::read_dir(run.join("episodes")).unwrap().count(),
        ITERATIONS * 6
    );
    let (ok, r, err) = replay(&run);
    assert!(ok, "{err}");
    assert!(r["difference"].is_null(), "{r}");
    assert_eq!(r["algorithm"], "gaifo-ppo", "{r}");
    assert_eq!(r["iterations"], ITERATIONS as u64, "{r}");
    assert_eq!(r["policies_checked"], ITERATIONS as u64 + 1, "{r}");
    assert_eq!(r["critics_checked"], ITERATIONS as u64 + 1, "{r}");
    assert_eq!(r["tables_checked"], 0, "{r}");
    assert!(err.contains("equal"), "{err}");

    // The second noisy episode of version 3 changed by 1e-9 in one state value: iterations 1
    // and 2 still equal, the policy of update 3 differs.
    let path = episodes_of(&run, 3)[1].clone();
    nudge(&path, 7 * 12 + 2, 1e-9);
    rerecord(&run, &path);
    let (ok, r, err) = replay(&run);
    assert!(!ok, "a difference exits non-zero");
    let d = &r["difference"];
    assert_eq!(d["iteration"], 3, "{r}");
    assert_eq!(d["array"], "policy", "{r}");
    assert!(
        d["file"]
            .as_str()
            .unwrap()
            .ends_with("iter_003_policy.json"),
        "{r}"
    );
    assert_ne!(d["recorded"], d["replayed"], "{r}");
    assert!(d["index"][0].as_u64().unwrap() > 0, "{r}");
    assert!(err.contains("first difference at iteration 3"), "{err}");
    assert_eq!(r["policies_checked"], ITERATIONS as u64 + 1, "{r}");
    std::fs::remove_dir_all(&dir).ok();
}

/// `learner dataset export --format mcap RUN OUT.mcap`: every channel with a JSON Schema, the
/// message counts the run implies, log times on one time line, values as recorded.
#[test]
fn a_recorded_run_exports_as_mcap_and_reads_back() {
    let dir = scratch("mcap");
    let run = recorded_run(&dir);
    let file = dir.join("out").join("run.mcap");
    let (ok, err) = learner(&[
        "dataset",
        "export",
        "--format",
        "mcap",
        run.to_str().unwrap(),
        file.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let bytes = std::fs::read(&file).unwrap();
    let (episodes, t_len) = (ITERATIONS * 6, 20);
    let mut count = std::collections::BTreeMap::<String, usize>::new();
    let mut last_time = 0;
    let mut first_state = None;
    let mut tables = Vec::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let ch = &m.channel;
        assert_eq!(ch.message_encoding, "json");
        let schema = ch.schema.as_ref().unwrap();
        assert_eq!(schema.encoding, "jsonschema");
        serde_json::from_slice::<serde_json::Value>(&schema.data).unwrap();
        let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
        *count.entry(ch.topic.clone()).or_default() += 1;
        assert!(m.log_time >= last_time, "{} at {}", ch.topic, m.log_time);
        last_time = m.log_time;
        match ch.topic.as_str() {
            "/state" if first_state.is_none() => first_state = Some(v),
            "/table" => tables.push(v),
            "/joint_states" => {
                assert_eq!(schema.name, "sensor_msgs/JointState");
                assert_eq!(v["name"][2], "elbow_joint");
                assert_eq!(v["position"].as_array().unwrap().len(), 3);
            }
            _ => {}
        }
    }
    for topic in ["/joint_states", "/state", "/action"] {
        assert_eq!(count[topic], episodes * t_len, "{topic}");
    }
    assert_eq!(count["/episode"], episodes);
    assert_eq!(count["/table"], ITERATIONS + 1);
    // All episodes laid end to end at dt = 0.1 s; the last table (version 4, which ran no
    // episode) comes at the end of the last one.
    let end_ns = ((episodes * t_len) as f64 * 0.1 * 1e9).round() as u64;
    assert_eq!(last_time, end_ns);
    assert_eq!(tables.last().unwrap()["version"], ITERATIONS as u64 + 1);
    // Values as recorded: the first state of the first episode, the first table's checksum.
    let first = episodes_of(&run, 1)[0].clone();
    let (ep, _) = load_episode(&first).unwrap();
    let s = first_state.unwrap();
    assert_eq!(s["q"][1].as_f64().unwrap(), ep.x[1]);
    assert_eq!(s["ee_minus_goal"][0].as_f64().unwrap(), ep.x[6]);
    let t0 = load_stored(&run.join("iter_000_table.npz")).unwrap();
    assert_eq!(tables[0]["version"], 1);
    assert_eq!(tables[0]["checksum"], format!("{:#018x}", t0.checksum));
    std::fs::remove_dir_all(&dir).ok();
}

/// The topics and message counts a streaming reader gets from `bytes` (an MCAP file that may
/// lack its summary and footer: `IgnoreEndMagic`), and whether it met an error (a cut file).
fn stream_counts(bytes: &[u8]) -> (std::collections::BTreeMap<String, usize>, bool) {
    let mut count = std::collections::BTreeMap::<String, usize>::new();
    let opts = mcap::read::Options::IgnoreEndMagic.into();
    let Ok(stream) = mcap::MessageStream::new_with_options(bytes, opts) else {
        return (count, true);
    };
    for m in stream {
        match m {
            Ok(m) => *count.entry(m.channel.topic.clone()).or_default() += 1,
            Err(_) => return (count, true),
        }
    }
    (count, false)
}

/// `learner serve --mcap` writes `run.mcap` episode by episode ([`RunMcap`]): a writer that
/// dies after k episodes (never finished: no summary, no footer) leaves a file from which a
/// streaming reader reads exactly those k episodes, whatever part of episode k + 1 was
/// written when it died; finished, the file is complete and reads as the export does.
#[test]
fn a_killed_mcap_writer_leaves_its_complete_episodes_readable() {
    use learner::io::episode::recorded_episodes;
    use learner::io::run_mcap::{RunMcap, TableInfo};
    let dir = scratch("mcap-kill");
    let run = recorded_run(&dir);
    let episodes = recorded_episodes(&run.join("episodes")).unwrap();
    let t_len = episodes[0].1.horizon();
    let file = dir.join("streamed.mcap");
    let mut m = RunMcap::create(&file, ur5_shared::StateLayout::REACH3).unwrap();
    m.table(TableInfo::load(&run.join("iter_000_table.npz")).unwrap());
    let mut sizes = Vec::new();
    for (path, ep, origin) in &episodes[..5] {
        m.episode(path, ep, origin, &ur5_shared::config::TaskConfig::default())
            .unwrap();
        sizes.push(std::fs::metadata(&file).unwrap().len());
    }
    // The process dies here: nothing more is written (no summary, no footer).
    std::mem::forget(m);
    let bytes = std::fs::read(&file).unwrap();
    assert_eq!(bytes.len() as u64, sizes[4]);
    assert!(
        mcap::MessageStream::new(&bytes).map_or(true, |mut s| s.any(|m| m.is_err())),
        "a reader that needs the end magic reports the file as cut"
    );
    // Cut anywhere inside the 5th episode's chunk (a kill while its chunk was being written,
    // which the writer's buffer makes a short moment): the first four episodes whole; of the
    // fifth, at most the steps that reached the disk, never its `/episode` message.
    let (lo, hi) = (sizes[3] as usize, sizes[4] as usize);
    for cut in [lo, lo + 1, lo + 9, (lo + hi) / 2, hi - 1, hi] {
        let (count, _) = stream_counts(&bytes[..cut]);
        let k = count["/episode"];
        assert_eq!(count["/table"], 1, "cut at {cut}");
        for topic in ["/state", "/joint_states"] {
            let n = count[topic];
            if cut == lo || cut == hi {
                // Between two episodes: exactly the complete ones.
                assert_eq!(k, if cut == lo { 4 } else { 5 }, "cut at {cut}");
                assert_eq!(n, k * t_len, "{topic}, cut at {cut}");
            } else {
                // The 5th is there whole (the cut is in the index after its chunk) or not
                // announced by its `/episode` message.
                assert!(k == 4 || k == 5, "cut at {cut}: {count:?}");
                assert!(
                    (4 * t_len..=5 * t_len).contains(&n),
                    "{topic}: {n}, cut at {cut}"
                );
                assert!(k == 4 || n == 5 * t_len, "{topic}: {n}, cut at {cut}");
            }
        }
    }

    // Finished, the streamed file reads as the export's: every message, summary and footer.
    let mut m = RunMcap::create(&file, ur5_shared::StateLayout::REACH3).unwrap();
    m.add_run(&run).unwrap();
    let c = m.finish().unwrap();
    assert_eq!(c.episodes, episodes.len());
    let streamed = std::fs::read(&file).unwrap();
    let exported = dir.join("exported.mcap");
    learner::io::run_mcap::write_run_mcap(&run, &exported).unwrap();
    let (a, cut) = stream_counts(&streamed);
    assert!(!cut);
    assert_eq!(a, stream_counts(&std::fs::read(&exported).unwrap()).0);
    assert_eq!(a["/episode"], episodes.len());
    let n = mcap::MessageStream::new(&streamed).unwrap().count();
    assert_eq!(n, a.values().sum::<usize>());
    std::fs::remove_dir_all(&dir).ok();
}

/// Copies the run folder `from` (files and one level of folders) to `to`.
fn copy_run(from: &Path, to: &Path) {
    std::fs::remove_dir_all(to).ok();
    for e in walk(from) {
        let dest = to.join(e.strip_prefix(from).unwrap());
        std::fs::create_dir_all(dest.parent().unwrap()).unwrap();
        std::fs::copy(&e, &dest).unwrap();
    }
}

fn walk(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            out.extend(walk(&p));
        } else {
            out.push(p);
        }
    }
    out
}

/// A replay checks the whole run or fails naming what is missing or altered: the run's record
/// of its files (`files.jsonl`, written as the run goes) against the folder, then every
/// recorded checkpoint reached by the replay; a run of a build without the record is replayed
/// as far as its files go and says so.
#[test]
fn a_replay_accounts_for_every_recorded_file() {
    use learner::io::learned::{append_event, LearnedEvent, LEARNED};
    let dir = scratch("record");
    let pristine = recorded_run(&dir);
    let (ok, r, err) = replay(&pristine);
    assert!(ok, "{err}");
    // 4 tables, 4 critics, 4 learner states, 18 episodes.
    assert_eq!(r["files_verified"], 30, "{r}");
    assert!(err.contains("all 30 files of the run's record"), "{err}");

    let run = dir.join("edited");
    let fails_with = |edit: &dyn Fn(&Path), want: &str| {
        copy_run(&pristine, &run);
        edit(&run);
        let (ok, err) = learner(&["replay", run.to_str().unwrap()]);
        assert!(!ok, "{want}: accepted\n{err}");
        assert!(err.contains(want), "want {want:?}, got\n{err}");
    };
    let v2 = |run: &Path| episodes_of(run, 2)[1].clone();
    fails_with(
        &|r| std::fs::remove_file(v2(r)).unwrap(),
        "1 of the run's files are not as its record files.jsonl says: \
         episodes/000008_e000007_v0002.npz missing",
    );
    fails_with(
        &|r| std::fs::remove_file(r.join("iter_002_table.npz")).unwrap(),
        "iter_002_table.npz missing",
    );
    // One byte of one episode (its noisy flag, table version or a state: any byte).
    fails_with(
        &|r| {
            let p = v2(r);
            let mut b = std::fs::read(&p).unwrap();
            let k = b.len() / 2;
            b[k] ^= 1;
            std::fs::write(&p, b).unwrap();
        },
        "episodes/000008_e000007_v0002.npz altered (bytes 0..",
    );
    fails_with(
        &|r| std::fs::write(r.join("iter_004_table.npz"), b"x").unwrap(),
        "iter_004_table.npz not in files.jsonl",
    );
    fails_with(
        &|r| {
            let p = r.join(learner::io::files::FILES);
            let t = std::fs::read_to_string(&p).unwrap();
            let cut: String = t.lines().take(5).map(|l| format!("{l}\n")).collect();
            std::fs::write(&p, cut).unwrap();
        },
        "25 of the run's files are not as its record files.jsonl says",
    );
    fails_with(
        &|r| std::fs::remove_file(r.join(learner::io::files::FILES)).unwrap(),
        "has no files.jsonl, the record of its files that its run.json says the run kept",
    );
    fails_with(
        &|r| {
            let p = r.join("run.json");
            let mut m: serde_json::Value =
                serde_json::from_slice(&std::fs::read(&p).unwrap()).unwrap();
            m["seed"] = 4.into();
            std::fs::write(&p, serde_json::to_vec(&m).unwrap()).unwrap();
        },
        "seed 4 but settings.seed 0: the run's manifest was altered",
    );

    // An appended list of what was learned (as `learner serve` keeps it), then cut.
    let learned_v1 = |r: &Path| {
        let names: Vec<String> = episodes_of(r, 1)
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        let list = r.join("episodes").join(LEARNED);
        let from = learner::io::files::len(&list);
        append_event(
            &r.join("episodes"),
            &LearnedEvent::Learned {
                iteration: 1,
                version: 1,
                noisy: names[..5].to_vec(),
                eval: names[5].clone(),
                more_evals: Vec::new(),
            },
        )
        .unwrap();
        learner::io::files::note_appended(r, &list, from).unwrap();
    };
    fails_with(
        &|r| {
            learned_v1(r);
            std::fs::write(r.join("episodes").join(LEARNED), b"").unwrap();
        },
        "episodes/learned.jsonl altered (0 bytes, the record says",
    );
    // A list that stops after version 1: the replay cannot reach the later checkpoints.
    fails_with(
        &learned_v1,
        "the replay ended after 1 iterations, before 4 recorded checkpoint file(s) of the run \
         (iter_002_critic.json, iter_002_table.npz, iter_003_critic.json, …)",
    );
    // A published table's copy (`tables/vVERSION.npz`, as `learner serve` writes them):
    // compared when there, missing when deleted.
    let table_copy = |r: &Path| {
        std::fs::create_dir_all(r.join("tables")).unwrap();
        let t = r.join("tables/v0003.npz");
        std::fs::copy(r.join("iter_002_table.npz"), &t).unwrap();
        rerecord(r, &t);
    };
    copy_run(&pristine, &run);
    table_copy(&run);
    let (ok, r, err) = replay(&run);
    assert!(ok, "{err}");
    assert_eq!(r["tables_checked"], 5, "{r}");
    fails_with(
        &|r| {
            table_copy(r);
            std::fs::remove_file(r.join("tables/v0003.npz")).unwrap();
        },
        "tables/v0003.npz missing",
    );

    // A NaN in a recorded episode (the file rewritten as the run's own): named with the file,
    // step and state, not as a covariance that is not positive definite.
    copy_run(&pristine, &run);
    let p = v2(&run);
    nudge(&p, 3 * 12 + 10, f64::NAN);
    rerecord(&run, &p);
    let (ok, err) = learner(&["replay", run.to_str().unwrap()]);
    assert!(!ok);
    assert!(
        err.contains("000008_e000007_v0002.npz: step 3: ee_vel_y = NaN"),
        "{err}"
    );
    // A gain table passed as a policy file says what it is.
    let (ok, err) = learner(&[
        "policy",
        "eval",
        "--policy",
        run.join("iter_001_table.npz").to_str().unwrap(),
        "--goal",
        "-0.45,-0.25,0.25",
    ]);
    assert!(!ok);
    assert!(err.contains("this is a gain table"), "{err}");
    assert!(!err.contains("schema_version"), "{err}");

    // A run of a build without the record: replayed as far as its files go, and said so.
    copy_run(&pristine, &run);
    forget_record(&run);
    std::fs::remove_file(v2(&run)).unwrap();
    let (ok, r, err) = replay(&run);
    assert!(ok, "{err}");
    assert!(r["files_verified"].is_null(), "{r}");
    assert!(
        r["note"].as_str().unwrap().contains("has no files.jsonl"),
        "{r}"
    );
    assert!(err.contains("equal as far as found"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}
