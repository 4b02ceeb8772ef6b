//! `learner experiment NAME --slurm DIR | --k8s DIR`: writes (and with `--submit`, submits)
//! the scheduler scripts of [`crate::experiment::scheduler`].

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::Context;

use super::experiment::ExperimentArgs;
use crate::experiment::scheduler::SweepPlan;
use crate::experiment::{ExperimentConfig, ExperimentName};

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
    args: &ExperimentArgs,
    name: ExperimentName,
    cfg: &ExperimentConfig,
) -> anyhow::Result<()> {
    anyhow::ensure!(
        name.trains_one_expert(),
        "--slurm/--k8s sweep the experiments that train one expert (comparison, stability, \
         ablation), not {}",
        name.as_str()
    );
    cfg.validate(name)?;
    if let Some(d) = &args.demos {
        crate::io::demos::load_checked(d, &cfg.lqr_gaifo.sim)
            .with_context(|| format!("--demos {}", d.display()))?;
    }
    let mut fwd: Vec<String> = Vec::new();
    if let Some(s) = args.seeds {
        fwd.extend(["--seeds".into(), s.to_string()]);
    }
    if let Some(i) = args.iterations {
        fwd.extend(["--iterations".into(), i.to_string()]);
    }
    if let Some(s) = args.common.seed {
        fwd.extend(["--seed".into(), s.to_string()]);
    }
    if let Some(c) = &args.common.config {
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
        demos: args.demos.as_deref().map(absolute).transpose()?,
        partition: args.partition.clone(),
        time: args.time.clone(),
        cpus: args.threads.unwrap_or(1).max(1),
    };
    plan.validate()?;
    if args.k8s.is_some() {
        for p in plan.write_k8s(&args.image, &args.claim)? {
            eprintln!("wrote {}", p.display());
        }
        println!("bash {}", plan.dir.join("submit-k8s.sh").display());
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
