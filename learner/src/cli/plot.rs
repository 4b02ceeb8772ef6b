//! `learner plot arm RUN_DIR`: the filmstrip PNG and the animated GIF of the arm reaching
//! ([`crate::film`]).

use std::path::PathBuf;

use clap::{Args, Subcommand};

/// `learner plot …`.
#[derive(Subcommand, Debug)]
pub enum PlotCmd {
    /// The arm reaching, expert against the imitator at a few iterations, side and top views:
    /// RUN_DIR/arm_filmstrip.png and RUN_DIR/arm.gif (or in --out). The controllers of the run
    /// (`iter_NNN_table.npz`, `expert/expert_table.npz`) are run again without noise on the
    /// default arm: a `learner train` run does not record its noise-free episodes' states.
    Arm(ArmArgs),
}

/// Arguments of `learner plot arm`.
#[derive(Args, Debug)]
pub struct ArmArgs {
    /// The `--out` folder of a `learner train` run.
    pub run_dir: PathBuf,
    /// The run's demonstrations (the task and, beside them, `expert_table.npz`)
    /// [default: those RUN_DIR/run.json names, checked against its hash; without run.json,
    /// RUN_DIR/expert/demos.npz].
    #[arg(long)]
    pub demos: Option<PathBuf>,
    /// Imitator iterations to draw (evenly spread from the first to the last checkpoint).
    #[arg(long, default_value_t = 3)]
    pub iterations: usize,
    /// Moments in the filmstrip.
    #[arg(long, default_value_t = 5)]
    pub frames: usize,
    /// Steps per GIF frame.
    #[arg(long, default_value_t = 2)]
    pub stride: usize,
    /// Output folder [default: RUN_DIR].
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// The demonstrations to draw: those the run's `run.json` names (or `--demos`, their new
/// place), with the run's hash; a folder without `run.json` (or an expert run, which has none)
/// uses `--demos` or RUN_DIR/expert/demos.npz.
fn run_demos(a: &ArmArgs) -> anyhow::Result<PathBuf> {
    let m = crate::io::manifest::read(&a.run_dir)?;
    Ok(match (m, &a.demos) {
        (Some(m), d) if m.demos_hash != "-" => crate::replay::demos_path(&m, d.as_deref())?,
        (_, Some(d)) => d.clone(),
        (_, None) => super::train::default_demos_path(&a.run_dir),
    })
}

/// Runs `learner plot …`.
pub fn run(cmd: PlotCmd) -> anyhow::Result<()> {
    let PlotCmd::Arm(a) = cmd;
    let demos = run_demos(&a)?;
    let (motions, goal, dt) = crate::film::run_motions(&a.run_dir, &demos, a.iterations)?;
    let out = a.out.clone().unwrap_or_else(|| a.run_dir.clone());
    crate::io::create_dir(&out)?;
    let png = out.join("arm_filmstrip.png");
    let gif = out.join("arm.gif");
    crate::film::filmstrip(&png, &motions, &goal, dt, a.frames)?;
    crate::film::animation(&gif, &motions, &goal, dt, a.stride)?;
    eprintln!(
        "{} motions ({}) -> {} and {}",
        motions.len(),
        motions
            .iter()
            .map(|m| m.label.as_str())
            .collect::<Vec<_>>()
            .join(", "),
        png.display(),
        gif.display()
    );
    Ok(())
}
