//! `soak`: the three processes (`hil-sim serve`, `rt-controller run`, `learner serve`) on one
//! iceoryx2 prefix for a while, with seeded SIGKILLs and restarts of each, then the reliability
//! figures: episodes completed and discarded, tables rejected, mixed versions, corrupted files
//! and commands outside the limits (`integration_tests::soak`).
//!
//! ```text
//! cargo run --release -p integration-tests --bin soak -- --minutes 30 --seed 1 [--json]
//! ```
//!
//! Kills: at most one every `--kill-every-s` K seconds (the gap is drawn in [K, 2K)), of a
//! process drawn among the running ones (the learner once its first checkpoint exists); the
//! killed process is restarted after a drawn 0–2 s with the arguments it needs (the learner
//! with `--resume` of its own folder). A process that exits by itself is restarted after 1 s
//! and counted. At the end every process gets SIGTERM and the run folder is scanned.
//! Lockstep, T = 30, the controller's default limits and N = 5 + 1 episodes per version.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Parser;
use integration_tests::soak::{scan_run, LogCounts, Scan};
use integration_tests::{cleanup_dead_nodes, unique_prefix};
use learner::process::{sibling, Spawned};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

/// Episode length (steps of 0.1 s): short episodes, many versions.
const T: usize = 30;
/// A stretch without a new recorded episode this long counts as a hang.
const HANG: Duration = Duration::from_secs(120);
/// A run that ends by itself sooner than this after its start failed to start; five such in a
/// row and the process never recovered.
const SHORT: Duration = Duration::from_secs(20);

#[derive(Parser)]
#[command(about = "Soak: the three processes with seeded random kills and restarts")]
struct Args {
    /// How long (minutes).
    #[arg(long, default_value_t = 30.0)]
    minutes: f64,
    /// Seed of the kill schedule and of the run.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// At most one kill every this many seconds (gaps drawn in [K, 2K)).
    #[arg(long, default_value_t = 10.0)]
    kill_every_s: f64,
    /// Folder for the configs, logs and the learner's run (must not exist or be empty).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Print one JSON line after the table.
    #[arg(long)]
    json: bool,
}

/// One of the three processes and its history.
struct Slot {
    name: &'static str,
    bin: PathBuf,
    proc: Option<Spawned>,
    killed: bool,
    restart_at: Option<Instant>,
    logs: Vec<PathBuf>,
    started: Instant,
    /// Exits by itself within [`SHORT`] of its start, in a row.
    failing: u32,
    stats: SlotStats,
}

#[derive(Clone, Debug, Default, Serialize)]
struct SlotStats {
    runs: u64,
    kills: u64,
    /// Exits nobody asked for (each restarted), with their code and last log line.
    unexpected_exits: u64,
    exits: Vec<String>,
    /// Exit code of the last run on the final SIGTERM (None: killed by a signal).
    final_code: Option<i32>,
}

#[derive(Debug, Serialize)]
struct Report {
    command: &'static str,
    minutes: f64,
    seed: u64,
    kill_every_s: f64,
    episodes_completed: u64,
    episodes_aborted: u64,
    episodes_recorded: u64,
    episodes_discarded_partial: u64,
    episodes_discarded_mixed: u64,
    tables_rejected: u64,
    table_versions: u64,
    mixed_versions: u64,
    corrupted_files: u64,
    commands_outside_limits: u64,
    hangs: u64,
    longest_stall_s: f64,
    never_recovered: Vec<&'static str>,
    logs: LogCounts,
    scan: Scan,
    sim: SlotStats,
    controller: SlotStats,
    learner: SlotStats,
    out: PathBuf,
}

fn main() -> std::process::ExitCode {
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("soak: error: {}", ur5_shared::report::error_line(e.chain()));
            std::process::ExitCode::FAILURE
        }
    }
}

fn run() -> anyhow::Result<()> {
    let args = Args::parse();
    anyhow::ensure!(
        args.minutes > 0.0 && args.minutes.is_finite() && args.kill_every_s > 0.0,
        "--minutes and --kill-every-s must be > 0"
    );
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("runs/soak-seed{}", args.seed)));
    if out.exists() && std::fs::read_dir(&out)?.next().is_some() {
        anyhow::bail!("{} is not empty: choose another --out", out.display());
    }
    std::fs::create_dir_all(out.join("logs"))
        .with_context(|| format!("creating {}", out.display()))?;
    let report = soak(&args, &out)?;
    print_table(&report);
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    }
    let bad = report.mixed_versions
        + report.corrupted_files
        + report.commands_outside_limits
        + report.hangs
        + report.never_recovered.len() as u64;
    anyhow::ensure!(bad == 0, "the soak found defects (see the table above)");
    Ok(())
}

fn soak(args: &Args, out: &Path) -> anyhow::Result<Report> {
    let prefix = unique_prefix(&format!("soak{}", args.seed));
    let run = out.join("run");
    let write = |name: &str, text: String| -> anyhow::Result<String> {
        let p = out.join(name);
        std::fs::write(&p, text).with_context(|| format!("writing {}", p.display()))?;
        Ok(p.display().to_string())
    };
    let learner_cfg = write(
        "learner.toml",
        format!(
            "samples = 5\nseed = {}\niterations = 100000\npatience = 100000\nrandom_episodes = 1\n\
             [task]\nhorizon = {T}\n[serve]\nwait_report_s = 5.0\n",
            args.seed
        ),
    )?;
    let sim_cfg = write("sim.toml", format!("[task]\nhorizon = {T}\n"))?;
    let ctl_cfg = write(
        "controller.toml",
        format!(
            "seed = {}\nnoisy_episodes = {}\neval_episodes = {}\n[task]\nhorizon = {T}\n",
            args.seed,
            integration_tests::soak::CYCLE.0,
            integration_tests::soak::CYCLE.1
        ),
    )?;
    let run_s = run.display().to_string();
    let args_of = |name: &str| -> Vec<String> {
        let v: Vec<&str> = match name {
            "sim" => vec!["serve", "--config", &sim_cfg, "--prefix", &prefix, "--json"],
            "controller" => vec!["run", "--config", &ctl_cfg, "--prefix", &prefix, "--json"],
            _ => {
                let mut v = vec![
                    "serve",
                    "--config",
                    &learner_cfg,
                    "--prefix",
                    &prefix,
                    "--out",
                    &run_s,
                    "--json",
                ];
                // Resume its own folder once it holds a checkpoint; before that (the first
                // run, or killed before its first write) start it anew.
                if run.join("checkpoint.npz").exists() {
                    v.extend(["--resume", &run_s]);
                } else if run.exists() {
                    v.push("--force");
                }
                v
            }
        };
        v.into_iter().map(String::from).collect()
    };

    let mut slots: Vec<Slot> = [
        ("sim", "hil-sim"),
        ("controller", "rt-controller"),
        ("learner", "learner"),
    ]
    .into_iter()
    .map(|(name, bin)| {
        Ok(Slot {
            name,
            bin: sibling(bin)?,
            proc: None,
            killed: false,
            restart_at: Some(Instant::now()),
            logs: Vec::new(),
            started: Instant::now(),
            failing: 0,
            stats: SlotStats::default(),
        })
    })
    .collect::<anyhow::Result<_>>()?;

    let mut rng = ChaCha8Rng::seed_from_u64(args.seed);
    let start = Instant::now();
    let end = start + Duration::from_secs_f64(args.minutes * 60.0);
    let gap = |rng: &mut ChaCha8Rng| {
        Duration::from_secs_f64(args.kill_every_s * (1.0 + rng.random::<f64>()))
    };
    let mut next_kill = start + gap(&mut rng);
    let (mut episodes_seen, mut last_progress) = (0usize, Instant::now());
    let (mut hangs, mut longest_stall, mut in_hang) = (0u64, Duration::ZERO, false);
    let mut next_look = Instant::now();
    eprintln!(
        "soak: prefix `{prefix}`, {} min, seed {}, a kill every {}–{} s; run folder {}",
        args.minutes,
        args.seed,
        args.kill_every_s,
        2.0 * args.kill_every_s,
        run.display()
    );

    while Instant::now() < end {
        let now = Instant::now();
        for slot in &mut slots {
            // Exits.
            if let Some(p) = slot.proc.as_mut() {
                if let Some(status) = p.try_wait()? {
                    if !slot.killed {
                        slot.stats.unexpected_exits += 1;
                        let last = p.log().lines().last().unwrap_or("").to_string();
                        let msg = format!(
                            "{} run {} exited by itself ({status}) at {:.0} s: {last}",
                            slot.name,
                            slot.stats.runs,
                            start.elapsed().as_secs_f64()
                        );
                        eprintln!("soak: {msg}");
                        if slot.stats.exits.len() < 20 {
                            slot.stats.exits.push(msg);
                        }
                        slot.restart_at = Some(now + Duration::from_secs(1));
                        if now - slot.started < SHORT {
                            slot.failing += 1;
                        } else {
                            slot.failing = 0;
                        }
                    }
                    slot.proc = None;
                    cleanup_dead_nodes();
                }
            }
            // Restarts.
            if slot.proc.is_none() && slot.restart_at.is_some_and(|t| now >= t) {
                slot.stats.runs += 1;
                let log = out
                    .join("logs")
                    .join(format!("{}.{:03}.log", slot.name, slot.stats.runs));
                let argv = args_of(slot.name);
                let p = Spawned::spawn(&slot.bin, &argv, &log, Duration::from_secs(5))?
                    .named(slot.name);
                slot.logs.push(log);
                slot.proc = Some(p);
                slot.started = now;
                slot.killed = false;
                slot.restart_at = None;
            }
        }
        // Kills.
        if now >= next_kill {
            next_kill = now + gap(&mut rng);
            let has_checkpoint = run.join("checkpoint.npz").exists();
            let live: Vec<usize> = (0..slots.len())
                .filter(|&i| {
                    slots[i].proc.is_some() && (slots[i].name != "learner" || has_checkpoint)
                })
                .collect();
            if !live.is_empty() {
                let i = live[rng.random_range(0..live.len())];
                let slot = &mut slots[i];
                let p = slot.proc.as_mut().expect("live");
                p.signal(libc::SIGKILL);
                let _ = p.wait(Duration::from_secs(10));
                slot.proc = None;
                slot.killed = true;
                slot.failing = 0;
                slot.stats.kills += 1;
                cleanup_dead_nodes();
                slot.restart_at = Some(now + Duration::from_secs_f64(rng.random_range(0.0..2.0)));
                eprintln!(
                    "soak: {:.0} s: killed {} (run {})",
                    start.elapsed().as_secs_f64(),
                    slot.name,
                    slot.stats.runs
                );
            }
        }
        // Progress: new recorded episodes.
        if now >= next_look {
            next_look = now + Duration::from_secs(2);
            let n = std::fs::read_dir(run.join("episodes")).map_or(0, |d| d.count());
            if n > episodes_seen {
                episodes_seen = n;
                last_progress = now;
                in_hang = false;
            }
            let stall = now - last_progress;
            longest_stall = longest_stall.max(stall);
            if stall > HANG && !in_hang {
                in_hang = true;
                hangs += 1;
                eprintln!("soak: no new episode for {:.0} s", stall.as_secs_f64());
            }
        }
        std::thread::sleep(Duration::from_millis(50));
    }

    // Stop: the learner first (its summary), then the controller, then the arm.
    for name in ["learner", "controller", "sim"] {
        let slot = slots.iter_mut().find(|s| s.name == name).expect("slot");
        if let Some(mut p) = slot.proc.take() {
            p.signal(libc::SIGTERM);
            slot.stats.final_code = p.wait(Duration::from_secs(30)).ok().and_then(|r| r.0);
        }
    }
    cleanup_dead_nodes();

    let mut logs = LogCounts::default();
    for slot in &slots {
        for log in &slot.logs {
            let text = std::fs::read_to_string(log).unwrap_or_default();
            match slot.name {
                "controller" => logs.controller(&text),
                "learner" => logs.learner(&text),
                _ => {}
            }
        }
    }
    let scan = scan_run(&run);
    let never_recovered = slots
        .iter()
        .filter(|s| s.failing >= 5)
        .map(|s| s.name)
        .collect();
    let stats = |name: &str| {
        slots
            .iter()
            .find(|s| s.name == name)
            .expect("slot")
            .stats
            .clone()
    };
    Ok(Report {
        command: "soak",
        minutes: args.minutes,
        seed: args.seed,
        kill_every_s: args.kill_every_s,
        episodes_completed: logs.episodes_done,
        episodes_aborted: logs.episodes_aborted,
        episodes_recorded: scan.episode_files,
        episodes_discarded_partial: logs.discarded_partial,
        episodes_discarded_mixed: logs.discarded_mixed,
        tables_rejected: logs.tables_rejected,
        table_versions: scan.max_version,
        mixed_versions: scan.mixed_versions,
        corrupted_files: scan.corrupted,
        commands_outside_limits: scan.outside_limits,
        hangs,
        longest_stall_s: longest_stall.as_secs_f64(),
        never_recovered,
        logs,
        scan,
        sim: stats("sim"),
        controller: stats("controller"),
        learner: stats("learner"),
        out: out.to_owned(),
    })
}

fn print_table(r: &Report) {
    let rows: Vec<(&str, String)> = vec![
        (
            "minutes, seed, a kill every",
            format!(
                "{}, {}, {}–{} s",
                r.minutes,
                r.seed,
                r.kill_every_s,
                2.0 * r.kill_every_s
            ),
        ),
        (
            "kills / restarts (sim, controller, learner)",
            format!(
                "{}/{}, {}/{}, {}/{}",
                r.sim.kills,
                r.sim.runs - 1,
                r.controller.kills,
                r.controller.runs - 1,
                r.learner.kills,
                r.learner.runs - 1
            ),
        ),
        (
            "exits nobody asked for (sim, controller, learner)",
            format!(
                "{}, {}, {}",
                r.sim.unexpected_exits, r.controller.unexpected_exits, r.learner.unexpected_exits
            ),
        ),
        (
            "episodes completed (controller)",
            r.episodes_completed.to_string(),
        ),
        (
            "episodes aborted (controller)",
            r.episodes_aborted.to_string(),
        ),
        (
            "episodes recorded (learner files)",
            r.episodes_recorded.to_string(),
        ),
        (
            "episodes discarded: partial / mixed (learner)",
            format!(
                "{} / {}",
                r.episodes_discarded_partial, r.episodes_discarded_mixed
            ),
        ),
        (
            "tables rejected (controller)",
            r.tables_rejected.to_string(),
        ),
        ("table versions published", r.table_versions.to_string()),
        (
            "files scanned; temporaries left",
            format!("{}; {}", r.scan.files, r.scan.temporaries),
        ),
        ("mixed versions (must be 0)", r.mixed_versions.to_string()),
        ("corrupted files (must be 0)", r.corrupted_files.to_string()),
        (
            "commands outside the limits (must be 0)",
            r.commands_outside_limits.to_string(),
        ),
        (
            "hangs (no episode for 120 s; must be 0)",
            r.hangs.to_string(),
        ),
        (
            "longest stretch without a new episode",
            format!("{:.1} s", r.longest_stall_s),
        ),
        (
            "never recovered (must be none)",
            format!("{:?}", r.never_recovered),
        ),
    ];
    println!("| soak | |\n|---|---|");
    for (k, v) in rows {
        println!("| {k} | {v} |");
    }
    for p in &r.scan.problems {
        println!("problem: {p}");
    }
    for s in [&r.sim, &r.controller, &r.learner] {
        for e in &s.exits {
            println!("exit: {e}");
        }
    }
}
