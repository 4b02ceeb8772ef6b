//! `learner dataset`: demonstrations and recorded episodes out to the formats other tools read
//! (LeRobot v3.0, CSV), a check of demonstrations in any format `--demos` takes
//! (docs/design.md §4.12), and the LASA handwriting shapes as tool paths (§4.18).

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::{Args, Subcommand, ValueEnum};

use crate::io::foreign;
use crate::io::lerobot::{self, Trajectories};

/// Output formats of `learner dataset export`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Format {
    /// A LeRobot v3.0 dataset folder.
    Lerobot,
    /// One CSV file (`episode,time_s,<state names>`).
    Csv,
    /// One MCAP file of a recorded run (IN: the run folder, with episodes/ and its tables):
    /// joint states, states, actions, clamp interventions, episodes and tables as JSON
    /// messages (docs/design.md §4.14).
    Mcap,
}

/// `learner dataset …`.
#[derive(Subcommand, Debug)]
pub enum DatasetCmd {
    /// Write demonstrations (`demos.npz`) or recorded episodes (one `.npz` of `learner serve`
    /// or a folder of them, e.g. RUN/episodes) as a LeRobot v3.0 dataset folder or a CSV file;
    /// or a recorded run (RUN) as one MCAP file.
    Export(ExportArgs),
    /// Load demonstrations in any format `--demos` takes (.npz, LeRobot folder, .csv of states
    /// or of tool paths), check them against the arm model they name (ur5 if they name none)
    /// and print what they hold, with their tool paths' spread.
    Check(CheckArgs),
    /// Write a shape of the LASA handwriting dataset, placed in the arm's workspace, as a
    /// tool-path CSV file that `--demos` takes (docs/design.md §4.18); without SHAPE, list
    /// the shapes.
    Lasa(LasaArgs),
    /// Write a tool-path CSV file (e.g. of `dataset lasa`) as a playback file for `hil-sim
    /// ur-sim --playback`: each path a motion moved by hand between two rests, from one start
    /// pose, the wrist locked (or, for paths with the tool's orientation rx,ry,rz, the whole
    /// arm following it), so that `learner record` can be taught it (docs/ur.md, "Teaching a
    /// motion by hand").
    Playback(PlaybackArgs),
}

/// Arguments of `learner dataset playback`.
#[derive(Args, Debug)]
pub struct PlaybackArgs {
    /// Tool-path CSV file (`episode,t,x,y,z`, optionally `,rx,ry,rz`).
    pub paths: PathBuf,
    /// Output playback file (new: an existing one is never replaced).
    pub out: PathBuf,
    /// The arm the paths are solved on (its default wrist lock and tool point).
    #[arg(long, default_value = "ur5")]
    pub model: ur5_shared::UrModel,
    /// Rows per second of the file (Hz, 10 to 1000).
    #[arg(long, default_value_t = 100.0)]
    pub rate: f64,
    /// Seed of the rests, the returns and the tremor: the same seed and paths give the same
    /// file, bit for bit.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Print a one-line JSON summary on stdout.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `learner dataset lasa`.
#[derive(Args, Debug)]
pub struct LasaArgs {
    /// The shape (e.g. Sshape; case-insensitive); none: list them.
    pub shape: Option<String>,
    /// Output tool-path CSV file (required with SHAPE).
    pub out: Option<PathBuf>,
    /// The arm whose default goal is the shape's end (without --end).
    #[arg(long, default_value = "ur5")]
    pub model: ur5_shared::UrModel,
    /// Where the shape ends, "x,y,z" (m, base frame); default: the model's default goal.
    #[arg(long, value_parser = ur5_shared::config::parse_triple, allow_hyphen_values = true)]
    pub end: Option<[f64; 3]>,
    /// The plane the shape is drawn in.
    #[arg(long, value_enum, default_value = "facing")]
    pub plane: crate::io::lasa::Plane,
    /// The shape's larger extent (m).
    #[arg(long, default_value_t = 0.2)]
    pub size: f64,
    /// The drawings' mean duration (s).
    #[arg(long, default_value_t = 10.0)]
    pub duration: f64,
    /// The tool's orientation held along the drawings, "rx,ry,rz" (rotation vector, rad, base
    /// frame): written as the file's rx, ry, rz columns, which make it demonstrations of the
    /// whole arm with a pose goal (`learner experiment shapes` with `joints = 6` holds the
    /// orientation the three-joint arm ends with).
    #[arg(long, value_parser = ur5_shared::config::parse_triple, allow_hyphen_values = true)]
    pub rotation: Option<[f64; 3]>,
}

/// Arguments of `learner dataset export`.
#[derive(Args, Debug)]
pub struct ExportArgs {
    /// Output format.
    #[arg(long, value_enum, default_value = "lerobot")]
    pub format: Format,
    /// Demonstrations `.npz`, an episode `.npz` or a folder of episode files (mcap: a run
    /// folder of `learner serve` or `learner train --record-episodes`).
    pub input: PathBuf,
    /// Output folder (lerobot) or file (csv, mcap).
    pub out: PathBuf,
}

/// Arguments of `learner dataset check`.
#[derive(Args, Debug)]
pub struct CheckArgs {
    /// Demonstrations: `.npz`, LeRobot dataset folder or `.csv`.
    pub demos: PathBuf,
    /// Print a one-line JSON summary on stdout.
    #[arg(long)]
    pub json: bool,
}

/// The trajectories in `input`: demonstrations, else recorded episodes.
fn read_input(input: &Path) -> anyhow::Result<Trajectories> {
    if input.is_file() {
        match crate::io::demos::load(input) {
            Ok(d) => return Ok(foreign::from_demos(&d)),
            Err(demos_err) => {
                return foreign::from_episodes(input).map_err(|e| {
                    anyhow::anyhow!(
                        "{}: neither demonstrations ({demos_err}) nor a recorded episode ({e:#})",
                        input.display()
                    )
                })
            }
        }
    }
    Ok(foreign::from_episodes(input)?)
}

/// `path` made absolute with its symbolic links resolved, also when it does not exist yet
/// (its nearest existing ancestor resolved, the rest appended).
fn resolved(path: &Path) -> std::path::PathBuf {
    let mut rest = Vec::new();
    let mut p = path.to_path_buf();
    loop {
        if let Ok(c) = p.canonicalize() {
            return rest.into_iter().rev().fold(c, |acc, n| acc.join(n));
        }
        match (p.file_name().map(|n| n.to_owned()), p.parent()) {
            (Some(n), Some(parent)) => {
                rest.push(n);
                p = if parent.as_os_str().is_empty() {
                    std::path::PathBuf::from(".")
                } else {
                    parent.to_path_buf()
                };
            }
            _ => return path.to_path_buf(),
        }
    }
}

/// An export never overwrites its input or a file inside it (`dataset export --format csv X X`,
/// `--format mcap RUN RUN/run.json`), and a LeRobot export goes into a new or empty folder:
/// data files of an older dataset left beside the new `meta/info.json` would be read back with
/// it (docs/reliability.md).
fn check_export_target(input: &Path, out: &Path, format: Format) -> anyhow::Result<()> {
    let (i, o) = (resolved(input), resolved(out));
    anyhow::ensure!(
        !(o == i || (o.starts_with(&i) && o.exists()) || i.starts_with(&o)),
        "the export {} would overwrite its input {} (or a file in it): write it elsewhere",
        out.display(),
        input.display()
    );
    if format == Format::Lerobot {
        check_lerobot_target(out)?;
    }
    anyhow::ensure!(
        format == Format::Lerobot || !out.is_dir(),
        "{} is a folder: a {} export is one file",
        out.display(),
        if format == Format::Csv { "CSV" } else { "MCAP" }
    );
    Ok(())
}

/// A LeRobot dataset goes into a new or empty folder: data files of an older dataset left
/// beside the new `meta/info.json` would be read back with it (`dataset export`, `record`).
pub(crate) fn check_lerobot_target(out: &Path) -> anyhow::Result<()> {
    if !out.is_dir() {
        return Ok(());
    }
    let mut entries = std::fs::read_dir(out)
        .with_context(|| format!("reading {}", out.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()));
    if let Some(first) = entries.next() {
        anyhow::bail!(
            "{} already holds files (e.g. {}): a LeRobot export goes into a new or empty \
             folder, so that no older data file is read back with the new dataset; delete it or \
             choose another folder",
            out.display(),
            first.display()
        );
    }
    Ok(())
}

/// Runs `learner dataset …`.
pub fn run(cmd: DatasetCmd) -> anyhow::Result<()> {
    if let DatasetCmd::Export(a) = &cmd {
        check_export_target(&a.input, &a.out, a.format)?;
    }
    match cmd {
        DatasetCmd::Export(a) if a.format == Format::Mcap => {
            let c = crate::io::run_mcap::write_run_mcap(&a.input, &a.out)?;
            eprintln!(
                "{} episodes and {} tables of {} -> {} ({} messages: {})",
                c.episodes,
                c.tables,
                a.input.display(),
                a.out.display(),
                c.messages.values().sum::<u64>(),
                c.messages
                    .iter()
                    .map(|(t, n)| format!("{t} {n}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            );
            Ok(())
        }
        DatasetCmd::Export(a) => {
            let traj = read_input(&a.input)?;
            match a.format {
                Format::Lerobot => lerobot::export(&traj, &a.out)?,
                Format::Mcap => unreachable!("handled above"),
                Format::Csv => {
                    if let Some(dir) = a.out.parent().filter(|d| !d.as_os_str().is_empty()) {
                        crate::io::create_dir(dir)?;
                    }
                    foreign::write_csv(&traj, &a.out)?
                }
            }
            eprintln!(
                "{} trajectories of T = {} ({} actions) from {} -> {}",
                traj.count,
                traj.horizon,
                if traj.actions.is_some() {
                    "with"
                } else {
                    "without"
                },
                a.input.display(),
                a.out.display()
            );
            Ok(())
        }
        DatasetCmd::Lasa(a) => {
            use crate::io::lasa;
            let Some(name) = &a.shape else {
                println!("{}", lasa::SHAPES.join("\n"));
                return Ok(());
            };
            let out = a
                .out
                .as_ref()
                .context("give the output file: learner dataset lasa SHAPE OUT.csv")?;
            let shape = lasa::shape(name)?;
            let placement = lasa::Placement {
                plane: a.plane,
                end: a.end.unwrap_or_else(|| a.model.default_goal()),
                size: a.size,
                duration: a.duration,
                rotation: a.rotation,
            };
            let paths = lasa::place(&shape, &placement).map_err(anyhow::Error::msg)?;
            if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
                crate::io::create_dir(dir)?;
            }
            lasa::write_csv(&paths, out)?;
            eprintln!(
                "LASA {}: {} drawings, {} m in the {:?} plane ending at {:?} m, {} s -> {}",
                shape.name,
                paths.len(),
                a.size,
                a.plane,
                placement.end,
                a.duration,
                out.display()
            );
            Ok(())
        }
        DatasetCmd::Playback(a) => {
            anyhow::ensure!(
                !a.out.exists(),
                "{} exists: dataset playback writes a new file and never replaces one",
                a.out.display()
            );
            let sim = ur5_shared::config::SimConfig::for_model(a.model);
            let p = crate::playback::playback_of_file(&a.paths, &sim, a.rate, a.seed)?;
            if let Some(dir) = a.out.parent().filter(|d| !d.as_os_str().is_empty()) {
                crate::io::create_dir(dir)?;
            }
            std::fs::write(&a.out, p.to_csv())
                .with_context(|| format!("writing {}", a.out.display()))?;
            let motions = crate::io::tool_path::read(&a.paths)?.len();
            eprintln!(
                "{} motions of {} on the {} taught by hand between rests: {} rows, {:.1} s -> {}",
                motions,
                a.paths.display(),
                a.model,
                p.t.len(),
                p.duration(),
                a.out.display()
            );
            if a.json {
                println!(
                    "{}",
                    serde_json::json!({"command": "dataset playback", "model": a.model,
                        "motions": motions, "rows": p.t.len(), "duration_s": p.duration(),
                        "out": a.out})
                );
            }
            Ok(())
        }
        DatasetCmd::Check(a) => {
            let recorded = crate::io::demos::model_of(&a.demos)?;
            let model = recorded.unwrap_or_default();
            let sim = ur5_shared::config::SimConfig::for_model(model);
            let d = crate::io::demos::load_checked(&a.demos, &sim)?;
            let spread = imitation::iteration_log::demo_spread(&d);
            let summary = serde_json::json!({"command": "dataset check", "demos": a.demos,
                "model": model, "model_recorded": recorded.is_some(), "count": d.count,
                "horizon": d.horizon, "dt_s": d.dt, "goal_m": d.goal, "start_q_rad": d.start_q,
                "cost_random": d.cost_random, "cost_expert": d.cost_expert,
                "demo_spread_rmse_m": spread.map(|s| s.rmse_m),
                "demo_spread_dtw_m": spread.map(|s| s.dtw_m),
                "demo_spread_frechet_m": spread.map(|s| s.frechet_m)});
            if a.json {
                println!("{summary}");
            } else {
                if let Some(s) = spread {
                    eprintln!(
                        "tool path spread (each demonstration against the mean of the others): \
                         RMSE {:.4} m, DTW {:.4} m, Fréchet {:.4} m",
                        s.rmse_m, s.dtw_m, s.frechet_m
                    );
                }
                eprintln!(
                    "{}: {} demonstrations of T = {} at dt = {} s, goal {:?} m, start {:?} rad, \
                     C_random {:.4}, C_expert {:.4}: consistent with the {model}{}",
                    a.demos.display(),
                    d.count,
                    d.horizon,
                    d.dt,
                    d.goal,
                    d.start_q,
                    d.cost_random,
                    d.cost_expert,
                    if recorded.is_some() {
                        String::new()
                    } else {
                        format!(
                            ", assumed: the file names no arm model, and another arm's \
                             demonstrations can pass the {model}'s checks (end-effector points \
                             within 1 cm); train with the [sim] model of the arm they were \
                             recorded on"
                        )
                    }
                );
            }
            Ok(())
        }
    }
}
