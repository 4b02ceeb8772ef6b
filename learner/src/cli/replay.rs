//! `learner replay RUN_DIR`: the run's learning done again from its recorded episodes, every
//! table compared bit for bit ([`crate::replay`]).

use std::path::PathBuf;

use clap::Args;

/// Arguments of `learner replay`.
#[derive(Args, Debug)]
pub struct ReplayArgs {
    /// The `--out` folder of a `learner serve` run (resumed ones included), or of a
    /// `learner train --record-episodes` run (LQR+GAIfO, `--algo gaifo-ppo`, `mdgps`, `bco` or `replay-mean`).
    pub run_dir: PathBuf,
    /// The run's demonstrations, when they are no longer where `run.json` says (their hash
    /// must be the run's).
    #[arg(long)]
    pub demos: Option<PathBuf>,
    /// Print the report as one line of JSON on stdout.
    #[arg(long)]
    pub json: bool,
}

/// Runs `learner replay`; an error (exit 1) when the replay differs from the run.
pub fn run(args: ReplayArgs) -> anyhow::Result<()> {
    let r = crate::replay::replay(&args.run_dir, args.demos.as_deref())?;
    if args.json {
        println!("{}", serde_json::to_string(&r)?);
    }
    eprintln!(
        "replay of {} (`learner {}` {}, seed {}): {} iterations from {} of {} recorded episodes \
         (picked by {}{}); {} table files, {} critic and {} policy checkpoints compared",
        r.run.display(),
        r.run_command,
        r.algorithm,
        r.seed,
        r.iterations,
        r.episodes_used,
        r.episodes,
        r.selection,
        match r.resumes {
            0 => String::new(),
            k => format!(", {k} resume(s) redone"),
        },
        r.tables_checked,
        r.critics_checked,
        r.policies_checked
    );
    if let Some(note) = &r.note {
        eprintln!("note: {note}");
    }
    match &r.difference {
        None => {
            anyhow::ensure!(
                r.files_checked() > 0,
                "no recorded checkpoint to compare in {}",
                r.run.display()
            );
            match r.files_verified {
                Some(n) => eprintln!(
                    "equal: every recorded checkpoint is the replay's, bit for bit; all {n} \
                     files of the run's record present and unaltered"
                ),
                None => eprintln!(
                    "equal as far as found: every checkpoint found is the replay's, bit for \
                     bit (no record of the run's files: a missing one cannot be told)"
                ),
            }
            Ok(())
        }
        Some(d) => anyhow::bail!(
            "first difference at iteration {} (table version {}): {} `{}`{} recorded {}, replayed {}{}",
            d.iteration,
            d.version,
            d.file.display(),
            d.array,
            if d.index.is_empty() {
                String::new()
            } else {
                format!(" at {:?}", d.index)
            },
            d.recorded,
            d.replayed,
            if d.episodes.is_empty() {
                String::new()
            } else {
                format!(
                    "; learned from {}",
                    d.episodes
                        .iter()
                        .map(|p| p.file_name().unwrap_or_default().to_string_lossy())
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            }
        ),
    }
}
