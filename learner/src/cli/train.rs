//! `learner train`: imitation from state-only demonstrations.

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::{Args, ValueEnum};

use imitation::demos::Demos;
use imitation::gaifo::{GaifoConfig, GaifoLog};
use imitation::ppo::UpdateStats;
use imitation::settings::PathSettings;

use super::CommonArgs;
use crate::io::manifest::{self, Claim, Manifest};
use crate::run::{train, train_resumed};
use imitation::ppo::gaifo_ppo::GaifoPpoConfig;

mod baselines;

/// Which imitation algorithm.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Algo {
    /// LQR+GAIfO (Torabi et al. 2019, Algorithm 1).
    LqrGaifo,
    /// GAIfO with a PPO policy (the baseline).
    GaifoPpo,
    /// MDGPS: one neural-network policy for several goals (docs/design.md §6); --demos is a
    /// folder of `.npz` demonstrations, one file per goal.
    Mdgps,
    /// Off-policy GAIfO: the critic as the reward of TD3 with a replay buffer (the baseline
    /// built for sample efficiency, docs/design.md §1.8).
    GaifoTd3,
    /// BCO(α): behavioural cloning from observation, a baseline (docs/design.md §7).
    Bco,
    /// The naive baseline: the demonstrations' mean joint path as the commands, no learning
    /// (docs/design.md §7.3).
    ReplayMean,
}

/// Arguments of `learner train`.
#[derive(Args, Debug)]
pub struct TrainArgs {
    /// Demonstrations: a `.npz` from `learner expert`, a LeRobot v3.0 dataset folder or a CSV
    /// file (docs/design.md §4.2); state trajectories only are used. Without it the default
    /// expert (`learner expert`'s settings on this run's arm and seed) is trained first and its
    /// demonstrations are recorded into OUT/expert/ (about 15 s); with --resume DIR, DIR's own
    /// DIR/expert/demos.npz. For --algo mdgps, a folder of `.npz` demonstrations (one file per
    /// goal, in name order); required.
    #[arg(long)]
    pub demos: Option<PathBuf>,
    /// Goal pose of the tool, UR's p[x, y, z, rx, ry, rz] (m; rotation vector, rad; base
    /// frame): without --demos the default expert is trained for it (six joints, as `learner
    /// expert --goal-pose`); with --demos they must be demonstrations of that pose (a file of
    /// another task is refused, naming both dimensions). Not with --algo mdgps.
    #[arg(long, value_parser = ur5_shared::config::parse_pose, allow_hyphen_values = true)]
    pub goal_pose: Option<[f64; 6]>,
    /// Algorithm.
    #[arg(long, value_enum, default_value = "lqr-gaifo")]
    pub algo: Algo,
    /// Iterations; overrides the config.
    #[arg(long)]
    pub iterations: Option<usize>,
    /// Continue the LQR+GAIfO, MDGPS or GAIfO (TD3) run in DIR (its --out) from its latest complete
    /// checkpoint (iter_NNN_critic.json + iter_NNN_state.npz) up to --iterations in all, with
    /// the run's own demonstrations, config and seed: iterations are numbered on from NNN and
    /// rows are appended to DIR/gaifo_log.csv (DIR/mdgps_log.csv for MDGPS). The resume is
    /// exact: the whole learner state (critic with Adam moments, GMM dynamics prior and its data,
    /// previous controllers, step size, η, MDGPS's policy and its optimiser, every RNG position)
    /// was checkpointed, so tables and CSV rows (timing columns aside) are those of an
    /// uninterrupted run, bit for bit, wherever the run was stopped or killed. A BCO run
    /// (--algo bco) resumes the same way from its latest iter_NNN_state.npz.
    #[arg(long, value_name = "DIR")]
    pub resume: Option<PathBuf>,
    /// Start a new run in --out even though another run's files are there: they are deleted
    /// first (without it such a folder is refused; docs/design.md §4.4).
    #[arg(long)]
    pub force: bool,
    /// Record every episode (noisy and noise-free) into OUT/episodes/ as `learner serve` does
    /// (docs/design.md §4.3), so that `learner replay OUT` can redo the run and check it bit
    /// for bit; a resumed run records on when its folder has episodes/. LQR+GAIfO and
    /// --algo gaifo-ppo, mdgps, gaifo-td3, bco and replay-mean.
    #[arg(long)]
    pub record_episodes: bool,
    /// Worker threads for the episodes of an iteration, which run in parallel (0 = one per
    /// core); results are the same for any number (docs/design.md §5 D29).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// --config: for lqr-gaifo a `GaifoConfig` (keys `samples`, `iterations`, `init_var`,
    /// `critic_updates`, `adapt_step`, `psd_hessian`, `seed`; tables `sim`, `discriminator`,
    /// `algorithm`, `prior`, `fit`, `traj_opt`), for gaifo-ppo a `GaifoPpoConfig` (keys
    /// `samples`, `iterations`, `critic_updates`, `seed`; tables `sim`, `discriminator`, `ppo`),
    /// for mdgps an `MdgpsConfig` (key `kl_step`; tables `lqr_gaifo`, `policy`), for gaifo-td3
    /// a `GaifoTd3Config` (keys `samples`, `iterations`, `exploration_noise`,
    /// `updates_per_episode`, `buffer_capacity`, `reward_scale`, `critic_data`, `reward`,
    /// `seed`; tables `sim`, `discriminator`, `td3`).
    /// --out: per-iteration CSV, gain tables and critic checkpoints [default: runs/train; with
    /// --resume, DIR].
    #[command(flatten)]
    pub common: CommonArgs,
}

/// The end of a `learner train` run: the summary line on stderr and, with `--json`, the
/// one-line JSON summary on stdout (both algorithms). `spread`: the demonstrations' own path
/// RMSE spread (m), beside the noise-free episode's path RMSE. The headline of a reach
/// ([`report_motion`] with `motion` false).
pub fn report(
    logs: &[GaifoLog],
    algo: &str,
    seed: u64,
    out: &std::path::Path,
    json: bool,
    spread: Option<f64>,
) {
    report_motion(logs, algo, seed, out, json, spread, false);
}

/// How near a path RMSE is to the demonstrations' spread, as the ratio `path / spread`:
/// "on the path" at most 1 (as close to the mean as another demonstration), "near the path"
/// at most 2, "off the path" beyond (docs/design.md §5 D39).
pub fn path_verdict(ratio: f64) -> &'static str {
    if ratio <= 1.0 {
        "on the path"
    } else if ratio <= 2.0 {
        "near the path"
    } else {
        "off the path"
    }
}

/// [`report`]; with `motion` (demonstrations of a motion: a tool-path file) and a spread, the
/// headline is the path: path RMSE, its ratio to the demonstrations' spread and
/// [`path_verdict`], before the final distance; normalised performance, whose task cost is a
/// reach's, follows as such (JSON: `path_ratio`, `path_verdict`).
pub fn report_motion(
    logs: &[GaifoLog],
    algo: &str,
    seed: u64,
    out: &std::path::Path,
    json: bool,
    spread: Option<f64>,
    motion: bool,
) {
    let Some(last) = logs.last() else { return };
    let ratio = spread.filter(|_| motion).map(|s| last.path_rmse / s);
    let orientation = last.final_orientation_error_deg;
    let orientation_text = if orientation.is_nan() {
        String::new()
    } else {
        format!(", orientation error {orientation:.2}°")
    };
    match (ratio, spread) {
        (Some(r), Some(s)) => eprintln!(
            "done: {} — path RMSE {:.4} m = {r:.2} × the demonstrations' own spread {s:.4} m; \
             final distance {:.4} m{orientation_text} (normalised performance {:.3} on the \
             reaching task cost, which does not measure the path); log and checkpoints in {}",
            path_verdict(r),
            last.path_rmse,
            last.final_distance,
            last.performance,
            out.display()
        ),
        _ => {
            eprintln!(
                "done: normalised performance {:.3} (task cost {:.4}, final distance {:.4} m{orientation_text}); log and checkpoints in {}",
                last.performance,
                last.task_cost,
                last.final_distance,
                out.display()
            );
            if let Some(s) = spread {
                eprintln!(
                    "path RMSE {:.4} m against the demonstrations' mean path; their own spread {s:.4} m",
                    last.path_rmse
                );
            }
        }
    }
    if json {
        let best = logs
            .iter()
            .map(|l| l.performance)
            .fold(f64::NEG_INFINITY, f64::max);
        let mut line = serde_json::json!({"command": "train", "algo": algo, "iterations": logs.len(), "seed": seed,
            "final_performance": last.performance, "best_performance": best, "final_task_cost": last.task_cost,
            "final_distance_m": last.final_distance, "path_rmse_m": last.path_rmse,
            "demo_spread_rmse_m": spread, "out": out});
        if !orientation.is_nan() {
            line["final_orientation_error_deg"] = orientation.into();
        }
        if let Some(r) = ratio {
            line["path_ratio"] = r.into();
            line["path_verdict"] = path_verdict(r).into();
        }
        println!("{line}");
    }
}

impl TrainArgs {
    /// The output folder: `--out`, else the `--resume` folder, else `runs/train`.
    pub fn out_dir(&self) -> PathBuf {
        self.common
            .out
            .clone()
            .or_else(|| self.resume.clone())
            .unwrap_or_else(|| PathBuf::from("runs/train"))
    }
}

/// Where the default demonstrations of a run in `out` are recorded: `out/expert/demos.npz`.
pub fn default_demos_path(out: &Path) -> PathBuf {
    out.join("expert").join("demos.npz")
}

/// The demonstrations file of this run and whether the folder was already claimed. With
/// `--demos`, that file; with `--resume DIR` alone, DIR's [`default_demos_path`]; else `out` is
/// claimed for the run (`m`, recording no demonstrations yet, so that a folder holding another
/// run is refused before the expert trains) and the default expert is trained and recorded into
/// `out/expert/` ([`crate::run::train_and_record`], as `learner expert` does).
fn demos_file(
    args: &TrainArgs,
    seed: u64,
    sim: &ur5_shared::config::SimConfig,
    m: &Manifest,
) -> anyhow::Result<(PathBuf, bool)> {
    let out = args.out_dir();
    if let Some(p) = &args.demos {
        return Ok((p.clone(), false));
    }
    if args.resume.is_some() {
        let p = default_demos_path(&out);
        anyhow::ensure!(
            p.is_file(),
            "--resume {} without --demos uses the run's own {}, which is not there: pass the \
             run's --demos",
            out.display(),
            p.display()
        );
        return Ok((p, false));
    }
    let mut ecfg = imitation::expert::ExpertConfig {
        seed,
        task: ur5_shared::config::TaskConfig::for_model(sim.model),
        sim: sim.clone(),
        ..Default::default()
    };
    if let Some(p) = args.goal_pose {
        super::expert::set_goal_pose(&mut ecfg.task, sim, p, false)?;
    }
    manifest::claim(&out, m, Claim::New { force: args.force })?;
    let dir = out.join("expert");
    eprintln!(
        "no --demos: training the default expert for goal {:?} m (seed {seed}) and recording {} \
         demonstrations -> {}",
        ecfg.task.goal,
        ecfg.demos,
        dir.display()
    );
    let s = super::expert::train_with_progress(&ecfg, &dir)
        .context("recording the default demonstrations")?;
    super::expert::print_done(&s, ecfg.demos);
    Ok((s.demos, true))
}

/// Demonstrations that name no arm model (a CSV, a LeRobot dataset without the model field)
/// are taken to be the `[sim]` model's; their joint angles cannot tell another arm apart, so
/// the run says so.
fn warn_unrecorded_model(path: &Path, sim: &ur5_shared::config::SimConfig) -> anyhow::Result<()> {
    if crate::io::demos::model_of(path)?.is_none() {
        eprintln!(
            "note: {} names no arm model: taken to be the {} ([sim] model), which cannot be \
             checked; if they were recorded on another arm, set [sim] model to it",
            path.display(),
            sim.model
        );
    }
    Ok(())
}

/// Takes `out` for the run `m` as `claim` says, adopts a resumed run's files as they are
/// ([`crate::io::files::adopt`]) and, with `record`, creates `out/episodes/`, which the run
/// records into because it is there.
fn take_folder(record: bool, out: &Path, m: &Manifest, claim: Claim) -> anyhow::Result<()> {
    manifest::claim(out, m, claim)?;
    if claim == Claim::Resume {
        crate::io::files::adopt(out)?;
    }
    if record {
        crate::io::create_dir(out.join("episodes"))?;
    }
    Ok(())
}

/// The start of an in-process `learner train --algo ALGO` on settings `cfg` (run seed `seed`,
/// arm `sim`): a resumed run only in its own `--out`; the demonstrations ([`demos_file`])
/// loaded and checked against the arm ([`warn_unrecorded_model`] too); the run's manifest and
/// its output folder taken ([`take_folder`]: claimed, or adopted when resumed). Returns the
/// output folder and the demonstrations.
pub(super) fn open_run<S: serde::Serialize>(
    args: &TrainArgs,
    algo: &str,
    seed: u64,
    sim: &ur5_shared::config::SimConfig,
    cfg: &S,
) -> anyhow::Result<(PathBuf, Demos)> {
    let out = args.out_dir();
    if let Some(dir) = &args.resume {
        anyhow::ensure!(
            out == *dir,
            "--out {} and --resume {} differ: a resumed run continues in its own folder",
            out.display(),
            dir.display()
        );
    }
    let pre = Manifest::new("train", algo, seed, None, cfg)?;
    let (path, claimed) = demos_file(args, seed, sim, &pre)?;
    let demos = crate::io::demos::load_checked(&path, sim)?;
    if let Some(p) = args.goal_pose {
        check_goal_pose(&demos, &path, sim, p)?;
    }
    warn_unrecorded_model(&path, sim)?;
    let m = Manifest::new("train", algo, seed, Some(&path), cfg)?;
    let claim = match args.resume {
        Some(_) => Claim::Resume,
        // Claimed already: the folder holds only its run.json, replaced now.
        None => Claim::New {
            force: args.force || claimed,
        },
    };
    take_folder(args.record_episodes, &out, &m, claim)?;
    Ok((out, demos))
}

/// Demonstrations of the pose task `--goal-pose` `pose` asks for (on the arm of `sim`): a file
/// of another layout is refused naming both dimensions, one of another goal pose naming both
/// poses.
fn check_goal_pose(
    demos: &Demos,
    path: &Path,
    sim: &ur5_shared::config::SimConfig,
    pose: [f64; 6],
) -> anyhow::Result<()> {
    let mut task = ur5_shared::config::TaskConfig::for_model(sim.model);
    super::expert::set_goal_pose(&mut task, sim, pose, false)?;
    crate::io::demos::check_run_layout(demos, &task.layout(), path)?;
    let theirs = demos.goal_pose.expect("a pose task's layout");
    anyhow::ensure!(
        theirs.iter().zip(&pose).all(|(a, b)| (a - b).abs() <= 1e-9),
        "{}: demonstrations of the goal pose {}, not --goal-pose {}: give demonstrations of \
         that pose, or leave --goal-pose out to imitate theirs",
        path.display(),
        super::expert::pose_text(&theirs),
        super::expert::pose_text(&pose)
    );
    Ok(())
}

/// A resumed folder must hold a run of the algorithm asked for: said before anything reads
/// the demonstrations or the checkpoints, which differ in kind between algorithms (a folder of
/// goals for MDGPS, `mdgps.iteration` in its states).
pub(super) fn check_resumed_algo(args: &TrainArgs) -> anyhow::Result<()> {
    let Some(dir) = &args.resume else {
        return Ok(());
    };
    let algo = match args.algo {
        Algo::LqrGaifo => "lqr-gaifo",
        Algo::Mdgps => "mdgps",
        Algo::GaifoPpo => "gaifo-ppo",
        Algo::GaifoTd3 => "gaifo-td3",
        Algo::Bco => "bco",
        Algo::ReplayMean => "replay-mean",
    };
    if let Some(m) = manifest::read(dir)? {
        anyhow::ensure!(
            m.algo == algo,
            "{} holds a `learner {}` {} run, not {algo}: resume it with --algo {} and its own \
             --demos, or start a new run in another --out",
            dir.display(),
            m.command,
            m.algo,
            m.algo
        );
    }
    Ok(())
}

/// Runs `learner train`.
pub fn run(args: TrainArgs) -> anyhow::Result<()> {
    check_resumed_algo(&args)?;
    anyhow::ensure!(
        args.goal_pose.is_none() || args.algo != Algo::Mdgps,
        "--goal-pose gives one goal; --algo mdgps takes its goals from the --demos folder"
    );
    if args.algo == Algo::Mdgps {
        return run_mdgps(&args);
    }
    if args.algo == Algo::Bco {
        return baselines::run_bco(&args);
    }
    if args.algo == Algo::ReplayMean {
        return baselines::run_replay_mean(&args);
    }
    if args.algo == Algo::GaifoPpo {
        anyhow::ensure!(
            args.resume.is_none(),
            "--resume continues LQR+GAIfO runs only (not --algo gaifo-ppo)"
        );
        let mut pcfg: GaifoPpoConfig = args.common.settings()?;
        if let Some(i) = args.iterations {
            pcfg.iterations = i;
        }
        if let Some(s) = args.common.seed {
            pcfg.seed = s;
        }
        pcfg.validate()?;
        let (_, demos) = open_run(&args, "gaifo-ppo", pcfg.seed, &pcfg.sim, &pcfg)?;
        return run_ppo(&args, demos, &pcfg);
    }
    let mut cfg: GaifoConfig = args.common.settings()?;
    if let Some(i) = args.iterations {
        cfg.iterations = i;
    }
    if let Some(s) = args.common.seed {
        cfg.seed = s;
    }
    let motion = motion_defaults(&args, &mut cfg)?;
    // Every setting, before anything is printed or written (the run checks them again).
    cfg.validate()?;
    anyhow::ensure!(
        args.resume.is_none() || args.algo == Algo::LqrGaifo,
        "--resume continues LQR+GAIfO runs only (not --algo gaifo-ppo)"
    );
    let (out, demos) = open_run(&args, "lqr-gaifo", cfg.seed, &cfg.sim, &cfg)?;
    eprintln!(
        "LQR+GAIfO on {} demonstrations of T = {} (goal {:?} m), seed {}, -> {}{}",
        demos.count,
        demos.horizon,
        demos.goal,
        cfg.seed,
        out.display(),
        if args.resume.is_some() {
            " (resumed)"
        } else {
            ""
        }
    );
    let spread = imitation::iteration_log::demo_spread(&demos).map(|s| s.rmse_m);
    // A motion's progress line adds the path RMSE over the demonstrations' spread.
    let ratio_of = |l: &GaifoLog| spread.filter(|_| motion).map(|s| l.path_rmse / s);
    if motion && spread.is_some() {
        eprintln!(
            "a motion: [path] critic_phase = {}, tracking_weight = {} (docs/design.md §5 D39); \
             `path/spr` is the path RMSE over the demonstrations' own spread (<= 1: on the path)",
            cfg.path.critic_phase, cfg.path.tracking_weight
        );
        eprintln!("{} path/spr", GaifoLog::PROGRESS_HEADER);
    } else {
        eprintln!("{}", GaifoLog::PROGRESS_HEADER);
    }
    let start = match &args.resume {
        Some(dir) => crate::run::latest_checkpoint(dir).map_or(0, |(n, _, _)| n),
        None => 0,
    };
    let bar =
        crate::progress::Progress::new(cfg.iterations.saturating_sub(start) as u64, "iterations");
    let print = |l: &GaifoLog| match ratio_of(l) {
        Some(r) => bar.done_one(&format!("{} {r:>8.2}", l.progress_line())),
        None => bar.done_one(&l.progress_line()),
    };
    let logs = match &args.resume {
        Some(dir) => train_resumed(&cfg, demos, dir, print)?,
        None => train(&cfg, demos, Some(&out), print)?,
    };
    drop(bar);
    if logs.is_empty() {
        eprintln!(
            "done: {} already holds all {} iterations; nothing to resume",
            out.display(),
            cfg.iterations
        );
        if args.common.json {
            println!(
                "{}",
                serde_json::json!({"command": "train", "algo": "lqr-gaifo", "iterations": 0,
                    "seed": cfg.seed, "already_complete": true, "out": out})
            );
        }
    }
    report_motion(
        &logs,
        "lqr-gaifo",
        cfg.seed,
        &out,
        args.common.json,
        spread,
        motion,
    );
    Ok(())
}

/// Whether the run imitates a motion: its `--demos` is a tool-path file (docs/design.md
/// §4.17), or its settings turn the path's terms on (`[path]`, e.g. for a motion recorded by
/// `learner record`). A tool-path file without a `[path]` table in `--config` takes
/// [`PathSettings::for_motions`] (docs/design.md §5 D39). Reaches keep the paper's cost.
fn motion_defaults(args: &TrainArgs, cfg: &mut GaifoConfig) -> anyhow::Result<bool> {
    let paths = demos_are_paths(args);
    if paths && !config_has_table(args.common.config.as_deref(), "path")? {
        cfg.path = PathSettings::for_motions();
    }
    Ok(paths || !cfg.path.is_off())
}

/// Whether `--demos` is a tool-path file: a motion, whose summary leads with the path
/// ([`report_motion`]).
pub(super) fn demos_are_paths(args: &TrainArgs) -> bool {
    args.demos
        .as_deref()
        .is_some_and(crate::io::tool_path::is_tool_path_csv)
}

/// Whether the TOML file `config` (if any) has a top-level key `key`.
fn config_has_table(config: Option<&Path>, key: &str) -> anyhow::Result<bool> {
    let Some(p) = config else { return Ok(false) };
    let text =
        std::fs::read_to_string(p).with_context(|| format!("reading --config {}", p.display()))?;
    let v: toml::Table = text
        .parse()
        .with_context(|| format!("parsing --config {}", p.display()))?;
    Ok(v.contains_key(key))
}

/// The progress line of a GAIfO (PPO) iteration.
fn ppo_line(l: &GaifoLog, u: &UpdateStats) -> String {
    format!(
        "{:>4} {:>9.4} {:>7.3} {:>8.4} {:>9.4} {:>8.4} {:>9.2e} {:>6.3} {:>7.3} {:>9.3e} {:>7.1} {:>7.1}",
        l.iteration,
        l.task_cost,
        l.performance,
        l.final_distance,
        l.critic_loss,
        l.wasserstein,
        l.kl,
        u.clip_fraction,
        u.mean_std,
        u.value_loss,
        1e3 * (l.t_critic + l.t_cost + l.t_lqr),
        1e3 * l.t_execute
    )
}

/// `learner train --algo gaifo-ppo` with `pcfg` (its `--config` layered over
/// [`GaifoPpoConfig::default`], i.e. LQR+GAIfO's shared settings, then the command line).
fn run_ppo(args: &TrainArgs, demos: Demos, pcfg: &GaifoPpoConfig) -> anyhow::Result<()> {
    let pcfg = pcfg.clone();
    let out = args.out_dir();
    eprintln!(
        "GAIfO (PPO) on {} demonstrations of T = {} (goal {:?} m), seed {}, -> {}",
        demos.count,
        demos.horizon,
        demos.goal,
        pcfg.seed,
        out.display()
    );
    eprintln!(
        "{:>4} {:>9} {:>7} {:>8} {:>9} {:>8} {:>9} {:>6} {:>7} {:>9} {:>7} {:>7}",
        "iter",
        "task_cost",
        "perf",
        "final_m",
        "critic",
        "W1_est",
        "approx_kl",
        "clip",
        "std",
        "v_loss",
        "lrn_ms",
        "sim_ms"
    );
    let bar = crate::progress::Progress::new(pcfg.iterations as u64, "iterations");
    let spread = imitation::iteration_log::demo_spread(&demos).map(|s| s.rmse_m);
    let motion = demos_are_paths(args);
    let logs = crate::run::train_ppo(&pcfg, demos, Some(&out), |l, u| {
        bar.done_one(&ppo_line(l, u))
    })?;
    drop(bar);
    report_motion(
        &logs,
        "gaifo-ppo",
        pcfg.seed,
        &out,
        args.common.json,
        spread,
        motion,
    );
    Ok(())
}

/// `learner train --algo mdgps`: MDGPS in process on the demonstrations of the `--demos` folder
/// (one `.npz` per goal), with checkpoints before every iteration and `--resume`
/// ([`crate::run::train_mdgps`], [`crate::run::train_mdgps_resumed`]).
fn run_mdgps(args: &TrainArgs) -> anyhow::Result<()> {
    use imitation::mdgps::{MdgpsConfig, MdgpsLog};
    let mut cfg: MdgpsConfig = args.common.settings()?;
    if let Some(i) = args.iterations {
        cfg.lqr_gaifo.iterations = i;
    }
    if let Some(s) = args.common.seed {
        cfg.lqr_gaifo.seed = s;
    }
    cfg.validate()?;
    let out = args.out_dir();
    if let Some(dir) = &args.resume {
        anyhow::ensure!(
            out == *dir,
            "--out {} and --resume {} differ: a resumed run continues in its own folder",
            out.display(),
            dir.display()
        );
    }
    let folder = args.demos.as_deref().context(
        "--algo mdgps needs --demos DIR, a folder of .npz demonstrations, one file per goal",
    )?;
    let demos = crate::io::demos::load_goals(folder, &cfg.lqr_gaifo.sim)?;
    let seed = cfg.lqr_gaifo.seed;
    let m = Manifest::new("train", "mdgps", seed, Some(folder), &cfg)?;
    let claim = match args.resume {
        Some(_) => Claim::Resume,
        None => Claim::New { force: args.force },
    };
    take_folder(args.record_episodes, &out, &m, claim)?;
    eprintln!(
        "MDGPS on {} goals ({} demonstrations each, T = {}), seed {seed}, -> {}{}",
        demos.len(),
        demos[0].count,
        demos[0].horizon,
        out.display(),
        if args.resume.is_some() {
            " (resumed)"
        } else {
            ""
        }
    );
    let iterations = cfg.lqr_gaifo.iterations;
    let start = match &args.resume {
        Some(dir) => crate::run::latest_checkpoint(dir).map_or(0, |(n, _, _)| n),
        None => 0,
    };
    let bar = crate::progress::Progress::new(iterations.saturating_sub(start) as u64, "iterations");
    let print = |l: &MdgpsLog| bar.done_one(&l.progress_line());
    let logs = match &args.resume {
        Some(dir) => crate::run::train_mdgps_resumed(&cfg, demos, dir, print)?,
        None => crate::run::train_mdgps(&cfg, demos, &out, print)?,
    };
    drop(bar);
    let last = logs.last();
    eprintln!(
        "done: {} iterations run{}; log and checkpoints in {}",
        logs.len(),
        last.map_or(String::new(), |l| format!(
            ", mean normalised performance at the goals {:.3}",
            l.mean_performance()
        )),
        out.display()
    );
    if args.common.json {
        println!(
            "{}",
            serde_json::json!({"command": "train", "algo": "mdgps", "iterations": logs.len(),
                "seed": seed, "final_mean_performance": last.map(|l| l.mean_performance()),
                "out": out})
        );
    }
    Ok(())
}
