//! `learner experiment NAME --slurm DIR | --k8s DIR`: writes (and with `--submit`, submits)
//! the scheduler scripts of [`crate::experiment::scheduler`].

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::Context;

use crate::experiment::scheduler::{trains_one_expert, SweepPlan};
use crate::experiment::{ExperimentConfig, ExperimentName};

/// The flags of `learner experiment NAME` that write a sweep instead of running it.
#[derive(clap::Args, Debug)]
pub struct SweepArgs {
    /// Write a Slurm sweep into DIR: expert.sbatch (trains the expert once; left out with
    /// --demos), shards.sbatch (an array of --shards tasks after it), merge.sbatch (after the
    /// array, `afterok`, into DIR/merged/) and submit.sh; prints the `sbatch` lines.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["shard", "k8s", "expert_only"])]
    pub slurm: Option<PathBuf>,
    /// Write a Kubernetes sweep into DIR: k8s-expert.yaml (a Job training the expert once; left
    /// out with --demos), k8s-shards.yaml (an Indexed Job of --shards completions,
    /// `JOB_COMPLETION_INDEX`), k8s-merge.yaml (into DIR/merged/), all on the volume claim
    /// --claim mounted at DIR, and submit-k8s.sh (applies each once the one before completed).
    #[arg(long, value_name = "DIR", conflicts_with_all = ["shard", "expert_only"])]
    pub k8s: Option<PathBuf>,
    /// Shards of a --slurm or --k8s sweep.
    #[arg(long, default_value_t = 4)]
    pub shards: usize,
    /// Shards running at once (--slurm, --k8s).
    #[arg(long, default_value_t = 1)]
    pub parallel: usize,
    /// Slurm partition of every job (--slurm).
    #[arg(long)]
    pub partition: Option<String>,
    /// Slurm time limit of every job, HH:MM:SS (--slurm).
    #[arg(long, value_name = "HH:MM:SS")]
    pub time: Option<String>,
    /// Submit the --slurm sweep with `sbatch` and print its job ids.
    #[arg(long, requires = "slurm")]
    pub submit: bool,
    /// Container image with `learner` on its PATH (--k8s).
    #[arg(long, default_value = "learner:latest")]
    pub image: String,
    /// PersistentVolumeClaim shared by the Jobs (--k8s).
    #[arg(long, default_value = "sweep")]
    pub claim: String,
}

/// What every job of a sweep is given of the experiment's command line.
#[derive(Debug)]
pub struct JobArgs<'a> {
    /// `--seeds`, seeds per variant.
    pub seeds: Option<usize>,
    /// `--iterations`, per run.
    pub iterations: Option<usize>,
    /// `--seed`, the first seed.
    pub seed: Option<u64>,
    /// `--config`, the experiment's settings file.
    pub config: Option<&'a Path>,
    /// Demonstrations instead of the expert job.
    pub demos: Option<&'a Path>,
    /// Worker threads per job (also `--cpus-per-task`); 1 without.
    pub threads: Option<usize>,
}

fn absolute(p: &Path) -> anyhow::Result<PathBuf> {
    Ok(if p.is_absolute() {
        p.to_path_buf()
    } else {
        std::env::current_dir()?.join(p)
    })
}

/// Writes the sweep's scripts; submits them with `--submit`.
/// `cfg` is the experiment's settings, checked here so that a bad config fails before any job
/// is queued.
pub fn write(
    args: &SweepArgs,
    job: &JobArgs,
    name: ExperimentName,
    cfg: &ExperimentConfig,
) -> anyhow::Result<()> {
    anyhow::ensure!(
        trains_one_expert(name, cfg),
        "--slurm/--k8s sweep the experiments that train one expert (comparison, stability, \
         ablation on one goal), not {}",
        name.as_str()
    );
    cfg.validate(name)?;
    if let Some(d) = job.demos {
        crate::io::demos::load_checked(d, &cfg.lqr_gaifo.sim)
            .with_context(|| format!("--demos {}", d.display()))?;
    }
    let mut fwd: Vec<String> = Vec::new();
    if let Some(s) = job.seeds {
        fwd.extend(["--seeds".into(), s.to_string()]);
    }
    if let Some(i) = job.iterations {
        fwd.extend(["--iterations".into(), i.to_string()]);
    }
    if let Some(s) = job.seed {
        fwd.extend(["--seed".into(), s.to_string()]);
    }
    if let Some(c) = job.config {
        fwd.extend(["--config".into(), absolute(c)?.display().to_string()]);
    }
    let dir = absolute(args.slurm.as_ref().or(args.k8s.as_ref()).expect("checked"))?;
    let plan = SweepPlan {
        experiment: name.as_str().into(),
        learner: std::env::current_exe().context("the learner executable's path")?,
        dir,
        shards: args.shards,
        parallel: args.parallel,
        args: fwd,
        demos: job.demos.map(absolute).transpose()?,
        partition: args.partition.clone(),
        time: args.time.clone(),
        cpus: job.threads.unwrap_or(1).max(1),
    };
    plan.validate()?;
    if args.k8s.is_some() {
        for p in plan.write_k8s(&args.image, &args.claim)? {
            eprintln!("wrote {}", p.display());
        }
        // Quoted: the line is meant to be pasted into a shell.
        let submit = plan.dir.join("submit-k8s.sh").display().to_string();
        println!("bash {}", crate::experiment::scheduler::quote(&submit)?);
        return Ok(());
    }
    let files = plan.write_slurm()?;
    for p in &files {
        eprintln!("wrote {}", p.display());
    }
    let submit = plan.dir.join("submit.sh");
    if !args.submit {
        print!("{}", std::fs::read_to_string(&submit)?);
        return Ok(());
    }
    let out = Command::new("bash")
        .arg(&submit)
        .output()
        .with_context(|| format!("running {} (is sbatch on PATH?)", submit.display()))?;
    eprint!("{}", String::from_utf8_lossy(&out.stderr));
    anyhow::ensure!(
        out.status.success(),
        "{} failed: {}",
        submit.display(),
        out.status
    );
    print!("{}", String::from_utf8_lossy(&out.stdout));
    Ok(())
}
