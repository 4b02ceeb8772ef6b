//! The reliability page (docs/reliability.md): bad inputs and faults of the
//! defect classes, each tried on the release binaries as a user would, with what each gets now
//! (exit code and the first line of the message). The test renders the table and compares it
//! with the committed page, so the page stays true; `RELIABILITY_WRITE=1 cargo test --release
//! -p integration-tests --test suite reliability::` rewrites the generated part.

use std::path::{Path, PathBuf};
use std::process::Command;

use integration_tests::{bin, scratch};

const BEGIN: &str = "<!-- BEGIN GENERATED: tests/tests/suite/reliability.rs -->";
const END: &str = "<!-- END GENERATED -->";

/// One bad input or fault: its defect class, what is tried, the command.
struct Case {
    class: &'static str,
    what: &'static str,
    bin: &'static str,
    args: Vec<String>,
}

/// What a command got: exit code and the first line of its error (scratch paths as `<dir>`).
fn outcome(case: &Case, dir: &Path) -> (Option<i32>, String) {
    let out = Command::new(bin(case.bin))
        .args(&case.args)
        .current_dir(dir)
        .env("RUST_BACKTRACE", "0")
        .env("RUST_LIB_BACKTRACE", "0")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).replace(dir.to_str().unwrap(), "<dir>");
    // The message and, for an anyhow chain ("Caused by:"), its causes, on one line.
    let mut lines = stderr.lines();
    let first = lines
        .by_ref()
        .find_map(|l| l.split_once("Error: ").or_else(|| l.split_once("error: ")))
        .map(|(_, m)| m.to_owned());
    let causes: Vec<String> = lines
        .map(str::trim)
        .filter(|l| !l.is_empty() && *l != "Caused by:" && !l.starts_with("Usage:"))
        .map(|l| {
            l.split_once(": ")
                .filter(|(n, _)| n.parse::<u32>().is_ok())
                .map_or(l, |(_, m)| m)
                .to_owned()
        })
        .collect();
    let line = match first {
        Some(f) if causes.is_empty() => f,
        Some(f) => format!("{f}: {}", causes.join(": ")),
        None => "(no error message)".to_owned(),
    };
    // The run manifest's creation time changes from run to run.
    let line = match line.split_once("Unix time ") {
        Some((a, b)) => format!(
            "{a}Unix time <t>{}",
            b.trim_start_matches(|c: char| c.is_ascii_digit())
        ),
        None => line,
    };
    let mut line = line.replace('|', "\\|");
    if line.chars().count() > 220 {
        line = line.chars().take(217).collect::<String>() + "...";
    }
    (out.status.code(), line)
}

fn write(dir: &Path, name: &str, text: &str) -> String {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    name.to_owned()
}

fn s(v: &[&str]) -> Vec<String> {
    v.iter().map(|x| x.to_string()).collect()
}

/// Demonstrations (T = 30), an edited copy (states × 1e6), and a one-iteration run `run/`.
fn setup(dir: &Path) {
    let ecfg = imitation::expert::ExpertConfig {
        task: ur5_shared::config::TaskConfig {
            horizon: 30,
            ..Default::default()
        },
        iterations: 3,
        random_episodes: 2,
        demos: 2,
        ..Default::default()
    };
    let run = learner::run::expert(&ecfg, |_| {}).unwrap();
    let demos = learner::run::demos(&ecfg, &run).unwrap();
    learner::io::demos::save(&demos, &dir.join("demos.npz")).unwrap();
    let mut scaled = demos.clone();
    scaled.states.iter_mut().for_each(|v| *v *= 1e6);
    learner::io::demos::save(&scaled, &dir.join("scaled.npz")).unwrap();
    let other = imitation::demos::Demos {
        seed: 99,
        ..demos.clone()
    };
    learner::io::demos::save(&other, &dir.join("other.npz")).unwrap();
    learner_ok(
        dir,
        &[
            "train",
            "--demos",
            "demos.npz",
            "--iterations",
            "1",
            "--out",
            "run",
        ],
    );
    for r in ["norun", "critic1e300"] {
        copy_tree(&dir.join("run"), &dir.join(r));
    }
    std::fs::remove_file(dir.join("norun/gaifo_log.csv")).unwrap();
    let critic = dir.join("critic1e300/iter_001_critic.json");
    let mut j: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&critic).unwrap()).unwrap();
    for p in j["params"].as_array_mut().unwrap() {
        *p = serde_json::json!(1e300);
    }
    std::fs::write(&critic, serde_json::to_vec(&j).unwrap()).unwrap();

    // Second round: a recorded run with one episode deleted, one without its record of files,
    // one whose run.json seed was edited; demonstrations with dt = 100 s, a NaN end-effector
    // velocity, the costs swapped; a LeRobot export (fps edited to 1e-300) and a CSV export.
    learner_ok(
        dir,
        &[
            "train",
            "--demos",
            "demos.npz",
            "--iterations",
            "2",
            "--record-episodes",
            "--out",
            "rec",
        ],
    );
    for r in ["rec-lost", "rec-norecord", "rec-seed"] {
        copy_tree(&dir.join("rec"), &dir.join(r));
    }
    let mut eps: Vec<PathBuf> = std::fs::read_dir(dir.join("rec-lost/episodes"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    eps.sort();
    std::fs::remove_file(&eps[7]).unwrap();
    std::fs::remove_file(dir.join("rec-norecord/files.jsonl")).unwrap();
    let mpath = dir.join("rec-seed/run.json");
    let mut m: serde_json::Value = serde_json::from_slice(&std::fs::read(&mpath).unwrap()).unwrap();
    m["seed"] = 4.into();
    std::fs::write(&mpath, serde_json::to_vec(&m).unwrap()).unwrap();
    let edited = |name: &str, edit: &dyn Fn(&mut imitation::demos::Demos)| {
        let mut d = demos.clone();
        edit(&mut d);
        learner::io::demos::save(&d, &dir.join(name)).unwrap();
    };
    edited("slow.npz", &|d| d.dt = 100.0);
    edited("swapped.npz", &|d| {
        std::mem::swap(&mut d.cost_expert, &mut d.cost_random)
    });
    for (fmt, out) in [
        ("lerobot", "lr"),
        ("lerobot", "lr-fps"),
        ("lerobot", "lr-cost"),
        ("csv", "d.csv"),
    ] {
        learner_ok(
            dir,
            &["dataset", "export", "--format", fmt, "demos.npz", out],
        );
    }
    // The CSV with a NaN end-effector velocity (demonstration 1, step 4, column ee_vel_x).
    let text = std::fs::read_to_string(dir.join("d.csv")).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    let col = lines[0].split(',').position(|c| c == "ee_vel_x").unwrap();
    let mut f: Vec<String> = lines[1 + 30 + 4].split(',').map(str::to_owned).collect();
    f[col] = "NaN".into();
    lines[1 + 30 + 4] = f.join(",");
    std::fs::write(dir.join("nan.csv"), lines.join("\n") + "\n").unwrap();
    let ipath = dir.join("lr-fps/meta/info.json");
    let mut info: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&ipath).unwrap()).unwrap();
    info["fps"] = 1e-300.into();
    std::fs::write(&ipath, serde_json::to_vec(&info).unwrap()).unwrap();
    let cpath = dir.join("lr-cost/meta/info.json");
    let mut info: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&cpath).unwrap()).unwrap();
    info["ur5_task"]["cost_random"] = 1000.0.into();
    std::fs::write(&cpath, serde_json::to_vec(&info).unwrap()).unwrap();
}

/// Copies a folder tree.
/// Runs `learner ARGS` in `dir` for the cases' setup; panics with its stderr if it fails.
fn learner_ok(dir: &Path, args: &[&str]) {
    let st = Command::new(bin("learner"))
        .args(s(args))
        .current_dir(dir)
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
}

fn copy_tree(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            copy_tree(&p, &to.join(e.file_name()));
        } else {
            std::fs::copy(&p, to.join(e.file_name())).unwrap();
        }
    }
}

fn urdf_with(dir: &Path, name: &str, edit: impl Fn(String) -> String) -> String {
    let text = std::fs::read_to_string(hil_sim::model::bundled_urdf_path()).unwrap();
    write(dir, name, &edit(text))
}

fn cases(dir: &Path) -> Vec<Case> {
    let train = |what: &'static str, class: &'static str, extra: &[&str]| {
        let own_out = extra.iter().any(|a| *a == "--out" || *a == "--resume");
        let out: &[&str] = if own_out { &[] } else { &["--out", "out"] };
        Case {
            class,
            what,
            bin: "learner",
            args: [&["train", "--demos", "demos.npz"][..], out, extra]
                .concat()
                .into_iter()
                .map(str::to_owned)
                .collect(),
        }
    };
    let config = |what: &'static str, class: &'static str, file: &str, text: &str| Case {
        class,
        what,
        bin: "learner",
        args: s(&[
            "train",
            "--demos",
            "demos.npz",
            "--out",
            "out",
            "--config",
            &write(dir, file, text),
        ]),
    };
    let inspect = |what: &'static str, class: &'static str, extra: &[&str]| Case {
        class,
        what,
        bin: "hil-sim",
        args: [
            &["inspect"][..],
            if extra.contains(&"--q") {
                &[]
            } else {
                &["--q", "0,-1,1"][..]
            },
            extra,
        ]
        .concat()
        .into_iter()
        .map(str::to_owned)
        .collect(),
    };
    let nested = format!(
        "<robot name=\"deep\">{}{}</robot>",
        "<link name=\"a\">".repeat(200_000),
        "</link>".repeat(200_000)
    );
    vec![
        train(
            "`--out` holding another run (seed 5)",
            "1",
            &["--out", "run", "--seed", "5", "--iterations", "2"],
        ),
        config(
            "`samples = 1000000000`",
            "4",
            "samples.toml",
            "samples = 1000000000\n",
        ),
        inspect(
            "URDF with a duplicated link name",
            "4",
            &[
                "--urdf",
                &urdf_with(dir, "dup.urdf", |t| {
                    t.replacen("name=\"forearm_link\"", "name=\"upper_arm_link\"", 1)
                }),
            ],
        ),
        train(
            "`--iterations 1000000000000`",
            "5",
            &["--iterations", "1000000000000"],
        ),
        config(
            "`[discriminator] hidden = [1000000000]`",
            "5",
            "hidden.toml",
            "[discriminator]\nhidden = [1000000000]\n",
        ),
        inspect(
            "URDF nested 200k elements deep",
            "5",
            &["--urdf", &write(dir, "deep.urdf", &nested)],
        ),
        config(
            "unknown key in `[discriminator]`",
            "6",
            "unknown.toml",
            "[discriminator]\nbogus = 1\n",
        ),
        config(
            "unknown key in `[discriminator.adam]`",
            "6",
            "unknown2.toml",
            "[discriminator.adam]\nbogus = 1\n",
        ),
        config(
            "`critic_updates = 1000000000`",
            "7",
            "updates.toml",
            "critic_updates = 1000000000\n",
        ),
        config(
            "`batch_size = 1000000000`",
            "7",
            "batch.toml",
            "[discriminator]\nbatch_size = 1000000000\n",
        ),
        config(
            "`kl_step = -1`",
            "8",
            "kl.toml",
            "[algorithm]\nkl_step = -1.0\n",
        ),
        config(
            "`kl_step = nan`",
            "8",
            "klnan.toml",
            "[algorithm]\nkl_step = nan\n",
        ),
        config(
            "`init_var = 1e300`",
            "8",
            "initvar.toml",
            "init_var = 1e300\n",
        ),
        config(
            "`max_eta < min_eta`",
            "8",
            "eta.toml",
            "[traj_opt]\nmax_eta = 1e-9\n",
        ),
        config(
            "`max_clusters = 0`",
            "8",
            "clusters.toml",
            "[prior]\nmax_clusters = 0\n",
        ),
        config(
            "`regularization = -1`",
            "8",
            "reg.toml",
            "[fit]\nregularization = -1.0\n",
        ),
        train(
            "critic checkpoint with every parameter 1e300",
            "9",
            &["--resume", "critic1e300", "--iterations", "3"],
        ),
        Case {
            class: "10",
            what: "`--resume` with other demonstrations of the same T",
            bin: "learner",
            args: s(&[
                "train",
                "--demos",
                "other.npz",
                "--resume",
                "run",
                "--iterations",
                "3",
            ]),
        },
        train(
            "`--resume` with another seed",
            "10",
            &["--resume", "run", "--seed", "7", "--iterations", "3"],
        ),
        Case {
            class: "11",
            what: "demonstrations × 1e6",
            bin: "learner",
            args: s(&["train", "--demos", "scaled.npz", "--out", "out"]),
        },
        inspect(
            "URDF with a NaN joint origin",
            "12",
            &[
                "--urdf",
                &urdf_with(dir, "nan.urdf", |t| {
                    t.replacen("xyz=\"0 0 0.089159\"", "xyz=\"0 0 nan\"", 1)
                }),
            ],
        ),
        inspect("`--tau 1e300`", "12", &["--tau", "1e300,0,0"]),
        inspect(
            "URDF with a zero joint axis",
            "12",
            &[
                "--urdf",
                &urdf_with(dir, "axis.urdf", |t| {
                    t.replacen("axis xyz=\"0 0 1\"", "axis xyz=\"0 0 0\"", 1)
                }),
            ],
        ),
        inspect("`--q` beyond the joint limits", "12", &["--q", "0,-100,1"]),
        train(
            "`--out` that cannot be made",
            "13",
            &["--out", "demos.npz/sub"],
        ),
        train(
            "`--resume` of a folder without `gaifo_log.csv`",
            "14",
            &["--resume", "norun", "--iterations", "3"],
        ),
        Case {
            class: "B1",
            what: "`learner replay` of a run with one recorded episode deleted",
            bin: "learner",
            args: s(&["replay", "rec-lost"]),
        },
        Case {
            class: "B1",
            what: "`learner replay` of a run without its `files.jsonl`",
            bin: "learner",
            args: s(&["replay", "rec-norecord"]),
        },
        Case {
            class: "B1",
            what: "`learner replay` of a run whose `run.json` seed was edited",
            bin: "learner",
            args: s(&["replay", "rec-seed"]),
        },
        Case {
            class: "B3",
            what: "demonstrations with dt = 100 s",
            bin: "learner",
            args: s(&["dataset", "check", "slow.npz"]),
        },
        Case {
            class: "B3",
            what: "LeRobot `fps` 1e-300",
            bin: "learner",
            args: s(&["dataset", "check", "lr-fps"]),
        },
        Case {
            class: "B3",
            what: "`learner expert --threads 100000`",
            bin: "learner",
            args: s(&["expert", "--threads", "100000", "--out", "e"]),
        },
        Case {
            class: "B3",
            what: "`ur-sim --time-compression 1e308`",
            bin: "hil-sim",
            args: s(&["ur-sim", "--time-compression", "1e308"]),
        },
        Case {
            class: "B4",
            what: "NaN in an `ee_vel_x` of a demonstrations CSV",
            bin: "learner",
            args: s(&["dataset", "check", "nan.csv"]),
        },
        Case {
            class: "B4",
            what: "`cost_random` below `cost_expert`",
            bin: "learner",
            args: s(&["dataset", "check", "swapped.npz"]),
        },
        Case {
            class: "B5",
            what: "LeRobot export into a folder holding a dataset",
            bin: "learner",
            args: s(&[
                "dataset",
                "export",
                "--format",
                "lerobot",
                "demos.npz",
                "lr",
            ]),
        },
        Case {
            class: "B5",
            what: "`dataset export --format csv X X`",
            bin: "learner",
            args: s(&["dataset", "export", "--format", "csv", "d.csv", "d.csv"]),
        },
        Case {
            class: "B5",
            what: "`dataset export --format mcap RUN RUN/run.json`",
            bin: "learner",
            args: s(&[
                "dataset",
                "export",
                "--format",
                "mcap",
                "rec",
                "rec/run.json",
            ]),
        },
        Case {
            class: "C1",
            what: "`learner record --out` under a file",
            bin: "learner",
            args: s(&[
                "record",
                "--ur",
                "127.0.0.1",
                "--rtde-port",
                "1",
                "--out",
                &format!("{}/sub", write(dir, "afile", "x")),
            ]),
        },
        Case {
            class: "C1",
            what: "`learner record --format lerobot` into an older dataset's folder",
            bin: "learner",
            args: s(&[
                "record",
                "--ur",
                "127.0.0.1",
                "--rtde-port",
                "1",
                "--format",
                "lerobot",
                "--out",
                "lr",
            ]),
        },
        Case {
            class: "C6",
            what: "`playback-gen --out` an existing file",
            bin: "hil-sim",
            args: s(&[
                "playback-gen",
                "--motions",
                "1",
                "--out",
                &write(dir, "reaches.csv", "mine\n"),
            ]),
        },
        Case {
            class: "C7",
            what: "`playback-gen --motions 200000 --rate 1000`",
            bin: "hil-sim",
            args: s(&[
                "playback-gen",
                "--motions",
                "200000",
                "--rate",
                "1000",
                "--out",
                "big.csv",
            ]),
        },
        Case {
            class: "C7",
            what: "`--slurm DIR --shards 1000000`",
            bin: "learner",
            args: s(&[
                "experiment",
                "comparison",
                "--slurm",
                "sweep",
                "--shards",
                "1000000",
            ]),
        },
        Case {
            class: "C8",
            what: "`--resume` of an LQR+GAIfO run as MDGPS",
            bin: "learner",
            args: s(&[
                "train",
                "--algo",
                "mdgps",
                "--demos",
                "demos.npz",
                "--resume",
                "run",
                "--iterations",
                "3",
            ]),
        },
        Case {
            class: "C8",
            what: "`playback-gen` with `task.start_q` outside the limits",
            bin: "hil-sim",
            args: s(&[
                "playback-gen",
                "--config",
                &write(dir, "far.toml", "[task]\nstart_q = [0.0, -1.5, 4.0]\n"),
                "--out",
                "far.csv",
            ]),
        },
        Case {
            class: "C3",
            what: "`[arm.ros2] command_topic = \"/a//b\"`",
            bin: "rt-controller",
            args: s(&[
                "run",
                "--config",
                &write(
                    dir,
                    "topic.toml",
                    "mode = \"real_time\"\npacing = \"arm\"\n[arm]\nbackend = \"ros2\"\n\
                     [arm.ros2]\ncommand_topic = \"/a//b\"\n",
                ),
            ]),
        },
        Case {
            class: "C3",
            what: "`[arm.ros2] joints` naming no elbow",
            bin: "rt-controller",
            args: s(&[
                "run",
                "--config",
                &write(
                    dir,
                    "joints.toml",
                    "mode = \"real_time\"\npacing = \"arm\"\n[arm]\nbackend = \"ros2\"\n\
                     [arm.ros2]\njoints = [\"wrist_1_joint\", \"wrist_2_joint\", \"wrist_3_joint\", \
                     \"shoulder_pan_joint\", \"shoulder_lift_joint\", \"knee_joint\"]\n",
                ),
            ]),
        },
        Case {
            class: "C4",
            what: "a LeRobot dataset's `ur5_task.cost_random` edited to 1000",
            bin: "learner",
            args: s(&["dataset", "check", "lr-cost"]),
        },
        Case {
            class: "3",
            what: "controller config `[bounds] max_abs_k_mat = nan`",
            bin: "rt-controller",
            args: s(&[
                "run",
                "--config",
                &write(dir, "bounds.toml", "[bounds]\nmax_abs_k_mat = nan\n"),
            ]),
        },
    ]
}

/// The markers of a block generated from a measurement's record in `docs/results/`.
fn block(name: &str, table: &str) -> (String, String, String) {
    (
        format!("<!-- BEGIN GENERATED: {name} -->"),
        format!("<!-- END GENERATED: {name} -->"),
        table.to_owned(),
    )
}

/// A measurement's record, committed in `docs/results/` (the long fuzz run's output, the
/// soak's JSON line): the page shows what it says.
fn measured(name: &str) -> String {
    let path: PathBuf = [env!("CARGO_MANIFEST_DIR"), "..", "docs", "results", name]
        .iter()
        .collect();
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The table of the long fuzz run from its output: one row per `fuzz <decoder>: <n> cases,
/// <a> accepted, slowest <ms> ms, <s> s in all` line, then the tests' result line.
fn render_fuzz(log: &str) -> String {
    let mut t = String::from(
        "| decoder | cases | accepted | slowest case | time |\n|---|---|---|---|---|\n",
    );
    for l in log.lines() {
        let Some((name, rest)) = l.strip_prefix("fuzz ").and_then(|r| r.split_once(": ")) else {
            continue;
        };
        let f: Vec<&str> = rest.split(", ").collect();
        let [cases, accepted, slowest, time] = f[..] else {
            continue;
        };
        let num = |s: &str| s.split(' ').next().unwrap_or("").to_owned();
        let slowest = slowest.trim_start_matches("slowest ");
        let time = time.trim_end_matches(" in all");
        t.push_str(&format!(
            "| {name} | {} | {} | {slowest} | {time} |\n",
            num(cases),
            num(accepted)
        ));
    }
    let results: Vec<&str> = log
        .lines()
        .filter(|l| l.starts_with("test result:"))
        .collect();
    for r in results {
        t.push_str(&format!("\n{r}\n"));
    }
    t
}

/// The soak's figures from its JSON line.
fn render_soak(json: &str) -> String {
    let j: serde_json::Value = serde_json::from_str(json.trim()).expect("the soak's JSON line");
    let n = |k: &str| j[k].to_string();
    let p = |p: &str, k: &str| j[p][k].to_string();
    let rows = [
        (
            "minutes, seed, a kill every (s)",
            format!(
                "{}, {}, {}–{}",
                n("minutes"),
                n("seed"),
                n("kill_every_s"),
                2.0 * j["kill_every_s"].as_f64().unwrap_or(0.0)
            ),
        ),
        (
            "SIGKILLs: arm, controller, learner",
            format!(
                "{}, {}, {}",
                p("sim", "kills"),
                p("controller", "kills"),
                p("learner", "kills")
            ),
        ),
        (
            "exits nobody asked for: arm, controller, learner",
            format!(
                "{}, {}, {}",
                p("sim", "unexpected_exits"),
                p("controller", "unexpected_exits"),
                p("learner", "unexpected_exits")
            ),
        ),
        ("episodes completed (controller)", n("episodes_completed")),
        (
            "episodes aborted (controller: arm gone mid-episode)",
            n("episodes_aborted"),
        ),
        ("episodes recorded (learner, files)", n("episodes_recorded")),
        (
            "episodes discarded by the learner: partial / mixed",
            format!(
                "{} / {}",
                n("episodes_discarded_partial"),
                n("episodes_discarded_mixed")
            ),
        ),
        ("tables rejected (controller)", n("tables_rejected")),
        ("table versions published", n("table_versions")),
        (
            "files scanned; temporaries left by kills",
            format!("{}; {}", p("scan", "files"), p("scan", "temporaries")),
        ),
        ("**mixed versions** (must be 0)", n("mixed_versions")),
        ("**corrupted files** (must be 0)", n("corrupted_files")),
        (
            "**commands outside the limits** (must be 0)",
            n("commands_outside_limits"),
        ),
        ("hangs: no new episode for 120 s (must be 0)", n("hangs")),
        (
            "longest stretch without a new episode (s)",
            format!("{:.1}", j["longest_stall_s"].as_f64().unwrap_or(0.0)),
        ),
        ("processes that never recovered", n("never_recovered")),
    ];
    let mut t = String::from("| figure | value |\n|---|---|\n");
    for (k, v) in rows {
        t.push_str(&format!("| {k} | {v} |\n"));
    }
    t
}

fn render(rows: &[(Case, (Option<i32>, String))]) -> String {
    let mut t = String::from(
        "| class | bad input or fault | command | exit | what it gets |\n|---|---|---|---|---|\n",
    );
    for (c, (code, msg)) in rows {
        let exit = code.map_or("signal".to_owned(), |c| c.to_string());
        let cmd = format!("`{} {}`", c.bin, c.args.join(" ")).replace('|', "\\|");
        let cmd = if cmd.chars().count() > 120 {
            cmd.chars().take(117).collect::<String>() + "…`"
        } else {
            cmd
        };
        t.push_str(&format!(
            "| {} | {} | {} | {} | {} |\n",
            c.class, c.what, cmd, exit, msg
        ));
    }
    t
}

#[test]
fn the_reliability_page_is_true() {
    let dir = scratch("reliability");
    setup(&dir);
    let rows: Vec<_> = cases(&dir)
        .into_iter()
        .map(|c| {
            let o = outcome(&c, &dir);
            (c, o)
        })
        .collect();
    for (c, (code, msg)) in &rows {
        assert!(
            matches!(code, Some(1) | Some(2)),
            "class {} ({}): exit {code:?}, {msg}: a bad input must end with a clear error",
            c.class,
            c.what
        );
    }
    let blocks = [
        (BEGIN.to_owned(), END.to_owned(), render(&rows)),
        block("fuzz", &render_fuzz(&measured("fuzz.log"))),
        block("soak", &render_soak(&measured("soak.json"))),
    ];
    let page_path: PathBuf = [env!("CARGO_MANIFEST_DIR"), "..", "docs", "reliability.md"]
        .iter()
        .collect();
    let page = std::fs::read_to_string(&page_path).unwrap_or_default();
    let mut new = page.clone();
    for (begin, end, table) in &blocks {
        let (Some(b), Some(e)) = (new.find(begin.as_str()), new.find(end.as_str())) else {
            panic!("{} has no {begin} … {end} block", page_path.display());
        };
        new = format!("{}{begin}\n{table}{}", &new[..b], &new[e..]);
    }
    if std::env::var_os("RELIABILITY_WRITE").is_some() {
        std::fs::write(&page_path, new).unwrap();
    } else {
        assert_eq!(
            page, new,
            "docs/reliability.md is out of date: rerun with RELIABILITY_WRITE=1 and review the diff"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}
