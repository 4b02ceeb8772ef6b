//! Sweeps under a batch scheduler (docs/design.md §4.8): the scripts of
//! `learner experiment NAME --slurm DIR` (Slurm) and `--k8s DIR` (a Kubernetes Indexed Job).
//!
//! Slurm: `DIR/expert.sbatch` trains the experiment's expert once and writes
//! `DIR/expert/demos.npz` (left out when the user gives `--demos`), `DIR/shards.sbatch` is an
//! array job of N tasks that depends on it (task K runs `--shard K/N --demos …` into
//! `DIR/shard_K`), and `DIR/merge.sbatch` depends on the array (`afterok`) and joins the
//! shards into `DIR/merged/`. `DIR/submit.sh` submits the three with their dependencies.
//!
//! A shard task writes into a temporary folder and renames it to `DIR/shard_K` at its end, so
//! a retried or twice-run task leaves one whole shard (the same files: a job's result depends
//! only on its seed, settings and demonstrations) and a killed one leaves none; the merge then
//! names the missing shard.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use super::ExperimentName;

/// Whether every job of `name` learns from one expert's demonstrations, so that a sweep can
/// train it once (`--expert-only`, `--slurm`, `--k8s`): comparison, stability, ablation on one
/// goal (not with `cfg.ablation_workspace_goals` or `cfg.comparison_workspace_goals`).
pub fn trains_one_expert(name: ExperimentName, cfg: &super::ExperimentConfig) -> bool {
    match name {
        ExperimentName::Stability => true,
        // On the workspace goals every job trains its goal's expert itself.
        ExperimentName::Comparison => !cfg.comparison_workspace_goals,
        ExperimentName::Ablation => !cfg.ablation_workspace_goals,
        _ => false,
    }
}

/// Everything the scripts need.
#[derive(Clone, Debug)]
pub struct SweepPlan {
    /// Experiment name as the CLI spells it (`comparison`, …).
    pub experiment: String,
    /// The `learner` executable the scripts run (an absolute path: jobs start elsewhere).
    pub learner: PathBuf,
    /// Folder of the scripts and every output (absolute).
    pub dir: PathBuf,
    /// Shards N ≥ 1.
    pub shards: usize,
    /// Shards run at once (Slurm's `%K` array throttle; Kubernetes `parallelism`), ≥ 1.
    pub parallel: usize,
    /// Flags every command gets (`--seeds 4 --iterations 5 --config …`), already split.
    pub args: Vec<String>,
    /// Demonstrations to use instead of the expert job (absolute path).
    pub demos: Option<PathBuf>,
    /// Slurm partition (`#SBATCH --partition`).
    pub partition: Option<String>,
    /// Slurm time limit per job, `HH:MM:SS`.
    pub time: Option<String>,
    /// Worker threads per task (`--cpus-per-task`, `--threads`).
    pub cpus: usize,
}

/// Errors in a plan.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum PlanError {
    #[error("--shards must be at least 1")]
    NoShards,
    #[error("--shards {0}: at most {MAX_SHARDS} (Slurm's default MaxArraySize; the merge job names every shard's folder on one command line)")]
    TooManyShards(usize),
    #[error("the merge job's command line would be {0} bytes, more than the {MAX_COMMAND_BYTES} a command line may safely hold: fewer --shards or a shorter DIR")]
    MergeTooLong(usize),
    #[error("--parallel must be at least 1")]
    NoParallel,
    #[error("--time `{0}`: expected HH:MM:SS, e.g. 01:30:00")]
    Time(String),
    #[error("{0}: the scripts need an absolute path (jobs start in another folder)")]
    Relative(PathBuf),
    #[error("`{0}`: a character the scripts cannot quote (newline or NUL)")]
    Unquotable(String),
    #[error("`{0}`: not an image or claim name (letters, digits and - . _ / : @)")]
    K8sName(String),
}

/// The most shards a sweep may have: Slurm's default `MaxArraySize` (1001) takes array indices
/// up to 1000, and the merge job lists every shard's folder.
pub const MAX_SHARDS: usize = 1000;

/// The longest command line a generated script may run (bytes): half of Linux's usual
/// `ARG_MAX` (2 MiB), the other half left to the environment.
pub const MAX_COMMAND_BYTES: usize = 1 << 20;

/// Checks an `HH:MM:SS` time limit (hours any number of digits; minutes and seconds < 60).
pub fn check_time(t: &str) -> Result<(), PlanError> {
    let bad = || PlanError::Time(t.into());
    let parts: Vec<&str> = t.split(':').collect();
    if parts.len() != 3 || parts.iter().any(|p| p.is_empty()) {
        return Err(bad());
    }
    let n: Vec<u64> = parts
        .iter()
        .map(|p| {
            p.chars()
                .all(|c| c.is_ascii_digit())
                .then(|| p.parse().ok())
                .flatten()
                .ok_or_else(bad)
        })
        .collect::<Result<_, _>>()?;
    if n[1] >= 60 || n[2] >= 60 || parts[1].len() != 2 || parts[2].len() != 2 {
        return Err(bad());
    }
    Ok(())
}

/// One shell word, single-quoted unless it is plainly safe.
pub fn quote(s: &str) -> Result<String, PlanError> {
    if s.contains('\n') || s.contains('\0') {
        return Err(PlanError::Unquotable(s.into()));
    }
    let safe = !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_./=:,+%@".contains(c));
    Ok(if safe {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', r"'\''"))
    })
}

fn words<'a>(ws: impl IntoIterator<Item = &'a str>) -> Result<String, PlanError> {
    Ok(ws
        .into_iter()
        .map(quote)
        .collect::<Result<Vec<_>, _>>()?
        .join(" "))
}

impl SweepPlan {
    /// Checks the plan.
    pub fn validate(&self) -> Result<(), PlanError> {
        if self.shards == 0 {
            return Err(PlanError::NoShards);
        }
        if self.shards > MAX_SHARDS {
            return Err(PlanError::TooManyShards(self.shards));
        }
        if self.parallel == 0 || self.cpus == 0 {
            return Err(PlanError::NoParallel);
        }
        if let Some(t) = &self.time {
            check_time(t)?;
        }
        for p in [Some(&self.learner), Some(&self.dir), self.demos.as_ref()]
            .into_iter()
            .flatten()
        {
            if !p.is_absolute() {
                return Err(PlanError::Relative(p.clone()));
            }
        }
        let merge = self.merge_cmd()?.len();
        if merge > MAX_COMMAND_BYTES {
            return Err(PlanError::MergeTooLong(merge));
        }
        Ok(())
    }

    /// The demonstrations every shard uses.
    pub fn demos_path(&self) -> PathBuf {
        self.demos
            .clone()
            .unwrap_or_else(|| self.dir.join("expert").join("demos.npz"))
    }

    /// `learner experiment NAME <args> --threads C`, quoted.
    fn base_cmd(&self) -> Result<String, PlanError> {
        let cpus = self.cpus.to_string();
        let mut w: Vec<&str> = vec![path_str(&self.learner)?, "experiment", &self.experiment];
        w.extend(self.args.iter().map(String::as_str));
        w.extend(["--threads", &cpus]);
        words(w)
    }

    fn header(&self, name: &str, log: &str) -> Result<String, PlanError> {
        let mut s = String::from("#!/bin/bash\n");
        let _ = writeln!(s, "#SBATCH --job-name={}", quote(name)?);
        let _ = writeln!(s, "#SBATCH --cpus-per-task={}", self.cpus);
        let _ = writeln!(
            s,
            "#SBATCH --output={}",
            quote(path_str(&self.dir.join(log))?)?
        );
        if let Some(p) = &self.partition {
            let _ = writeln!(s, "#SBATCH --partition={}", quote(p)?);
        }
        if let Some(t) = &self.time {
            let _ = writeln!(s, "#SBATCH --time={t}");
        }
        s.push_str("set -euo pipefail\n");
        Ok(s)
    }

    /// `expert.sbatch`: trains the expert once into `DIR/expert/demos.npz`.
    pub fn slurm_expert(&self) -> Result<String, PlanError> {
        let mut s = self.header(&format!("{}-expert", self.experiment), "logs/expert-%j.out")?;
        let out = self.dir.join("expert");
        let _ = writeln!(
            s,
            "# Trains the expert once: every shard uses its demonstrations.\n\
             {} --expert-only --out {}",
            self.base_cmd()?,
            quote(path_str(&out)?)?
        );
        Ok(s)
    }

    /// The shell lines of one shard task, `K` the shell expression of its 1-based index.
    fn shard_body(&self, k: &str) -> Result<String, PlanError> {
        let dir = quote(path_str(&self.dir)?)?;
        let demos = quote(path_str(&self.demos_path())?)?;
        Ok(format!(
            "K={k}\n\
             N={n}\n\
             OUT={dir}/shard_${{K}}\n\
             # Into a temporary folder, renamed at the end: a retried or twice-run task leaves\n\
             # one whole shard_K (the same files, wall times aside), a killed one none.\n\
             TMP={dir}/.shard_${{K}}.$$.${{HOSTNAME:-host}}\n\
             rm -rf \"$TMP\"\n\
             {cmd} --demos {demos} --shard \"$K/$N\" --out \"$TMP\"\n\
             rm -rf \"$OUT\"\n\
             if ! mv -T \"$TMP\" \"$OUT\" 2>/dev/null; then\n\
             \x20 # A concurrent run of this task renamed its whole shard first.\n\
             \x20 test -f \"$OUT/shard.json\"\n\
             \x20 rm -rf \"$TMP\"\n\
             fi\n",
            n = self.shards,
            cmd = self.base_cmd()?,
        ))
    }

    /// `shards.sbatch`: the array job, task K runs shard K/N into `DIR/shard_K`.
    pub fn slurm_shards(&self) -> Result<String, PlanError> {
        let mut s = self.header(
            &format!("{}-shards", self.experiment),
            "logs/shard-%A_%a.out",
        )?;
        s = s.replacen(
            "set -euo",
            &format!(
                "#SBATCH --array=1-{}%{}\nset -euo",
                self.shards, self.parallel
            ),
            1,
        );
        s.push_str(&self.shard_body("$SLURM_ARRAY_TASK_ID")?);
        Ok(s)
    }

    /// `learner experiment merge DIR/shard_1 … DIR/shard_N`, quoted (`--out` to add).
    fn merge_cmd(&self) -> Result<String, PlanError> {
        let shards: Vec<String> = (1..=self.shards)
            .map(|k| path_str(&self.dir.join(format!("shard_{k}"))).map(str::to_string))
            .collect::<Result<_, _>>()?;
        let mut w: Vec<&str> = vec![path_str(&self.learner)?, "experiment", "merge"];
        w.extend(shards.iter().map(String::as_str));
        words(w)
    }

    /// The shell lines of the merge job: into a temporary folder that then replaces
    /// `DIR/merged`, the merge job's own output, so a retried merge job ends with the same
    /// files (`experiment merge` itself never replaces results it did not write).
    fn merge_body(&self) -> Result<String, PlanError> {
        let dir = quote(path_str(&self.dir)?)?;
        Ok(format!(
            "OUT={dir}/merged\n\
             TMP={dir}/.merged.$$.${{HOSTNAME:-host}}\n\
             rm -rf \"$TMP\"\n\
             {cmd} --out \"$TMP\"\n\
             rm -rf \"$OUT\"\n\
             mv -T \"$TMP\" \"$OUT\"\n",
            cmd = self.merge_cmd()?,
        ))
    }

    /// `merge.sbatch`: joins every shard into `DIR/merged/`.
    pub fn slurm_merge(&self) -> Result<String, PlanError> {
        let mut s = self.header(&format!("{}-merge", self.experiment), "logs/merge-%j.out")?;
        s.push_str(&self.merge_body()?);
        Ok(s)
    }

    /// `submit.sh`: the `sbatch` lines with their dependencies, printing the job ids.
    pub fn slurm_submit(&self) -> Result<String, PlanError> {
        let d = |f: &str| -> Result<String, PlanError> { quote(path_str(&self.dir.join(f))?) };
        let mut s = String::from("#!/bin/bash\nset -euo pipefail\n");
        let dep = if self.demos.is_none() {
            let _ = writeln!(
                s,
                "EXPERT=$(sbatch --parsable {} | cut -d';' -f1)",
                d("expert.sbatch")?
            );
            s.push_str("echo \"expert job $EXPERT\"\n");
            "--dependency=afterok:$EXPERT "
        } else {
            ""
        };
        let _ = writeln!(
            s,
            "SHARDS=$(sbatch --parsable {dep}{} | cut -d';' -f1)\n\
             echo \"shards job $SHARDS\"\n\
             MERGE=$(sbatch --parsable --dependency=afterok:$SHARDS {} | cut -d';' -f1)\n\
             echo \"merge job $MERGE\"",
            d("shards.sbatch")?,
            d("merge.sbatch")?
        );
        Ok(s)
    }

    /// The Kubernetes Jobs, in their order, as (file name, manifest): `k8s-expert.yaml`
    /// trains the expert (none with [`SweepPlan::demos`]), `k8s-shards.yaml` is an Indexed
    /// Job of N completions (completion index I runs shard I+1/N, the same rename as a Slurm
    /// task) and `k8s-merge.yaml` joins them. `image` has `learner` on its `PATH`; `DIR` is a
    /// shared volume (PersistentVolumeClaim `claim`) mounted at `DIR` in every pod. Jobs have
    /// no dependencies in Kubernetes: [`SweepPlan::k8s_submit`] applies each after the last.
    pub fn k8s_jobs(&self, image: &str, claim: &str) -> Result<Vec<(String, String)>, PlanError> {
        // Inside the image, `learner` is on the PATH.
        let p = SweepPlan {
            learner: "learner".into(),
            ..self.clone()
        };
        for v in [image, claim] {
            let ok = !v.is_empty()
                && v.chars()
                    .all(|c| c.is_ascii_alphanumeric() || "-._/:@".contains(c));
            if !ok {
                return Err(PlanError::K8sName(v.into()));
            }
        }
        // A JSON string is a YAML double-quoted scalar.
        let dir = serde_json::to_string(path_str(&self.dir)?).expect("a string serialises");
        let job = |name: &str, extra: &str, script: &str| {
            let script: String = script.lines().map(|l| format!("          {l}\n")).collect();
            format!(
                "apiVersion: batch/v1\nkind: Job\nmetadata:\n  name: {name}\nspec:\n{extra}  \
                 backoffLimit: 3\n  template:\n    spec:\n      restartPolicy: Never\n      \
                 containers:\n      - name: learner\n        image: {image}\n        \
                 resources: {{requests: {{cpu: \"{cpus}\"}}}}\n        \
                 command: [\"/bin/bash\", \"-c\"]\n        \
                 args:\n        - |\n          set -euo pipefail\n{script}        \
                 volumeMounts: [{{name: sweep, mountPath: {dir}}}]\n      \
                 volumes: [{{name: sweep, persistentVolumeClaim: {{claimName: {claim}}}}}]\n",
                cpus = self.cpus,
            )
        };
        let e = &self.experiment;
        let mut jobs = Vec::new();
        if self.demos.is_none() {
            let cmd = format!(
                "{} --expert-only --out {}",
                p.base_cmd()?,
                quote(path_str(&self.dir.join("expert"))?)?
            );
            jobs.push((
                "k8s-expert.yaml".into(),
                job(&format!("{e}-expert"), "", &cmd),
            ));
        }
        let extra = format!(
            "  completionMode: Indexed\n  completions: {}\n  parallelism: {}\n",
            self.shards, self.parallel
        );
        let body = p.shard_body("$((JOB_COMPLETION_INDEX + 1))")?;
        jobs.push((
            "k8s-shards.yaml".into(),
            job(&format!("{e}-shards"), &extra, &body),
        ));
        jobs.push((
            "k8s-merge.yaml".into(),
            job(&format!("{e}-merge"), "", &p.merge_body()?),
        ));
        Ok(jobs)
    }

    /// `submit-k8s.sh`: `kubectl apply` of each Job of [`SweepPlan::k8s_jobs`] once the one
    /// before it completed; stops when one fails (its `backoffLimit` spent).
    pub fn k8s_submit(&self, files: &[String]) -> Result<String, PlanError> {
        let mut s = String::from(
            "#!/bin/bash\nset -euo pipefail\n\
             # Waits for Job $1 to complete; exits when it failed.\n\
             wait_job() {\n  \
               while :; do\n    \
                 c=$(kubectl get job \"$1\" -o \
             jsonpath='{.status.conditions[?(@.status==\"True\")].type}')\n    \
                 case \" $c \" in\n    \
                 *\" Complete \"*) echo \"job $1 complete\"; return 0 ;;\n    \
                 *\" Failed \"*) echo \"job $1 failed: kubectl logs job/$1\" >&2; exit 1 ;;\n    \
                 esac\n    \
                 sleep 10\n  \
               done\n\
             }\n",
        );
        for f in files {
            let name = format!(
                "{}-{}",
                self.experiment,
                f.trim_start_matches("k8s-").trim_end_matches(".yaml")
            );
            let _ = writeln!(
                s,
                "kubectl apply -f {}\nwait_job {name}",
                quote(path_str(&self.dir.join(f))?)?
            );
        }
        Ok(s)
    }

    /// Writes the Slurm scripts into `DIR` (and `DIR/logs/`); returns the paths written.
    pub fn write_slurm(&self) -> std::io::Result<Vec<PathBuf>> {
        let mut files = vec![
            ("shards.sbatch", self.slurm_shards()),
            ("merge.sbatch", self.slurm_merge()),
            ("submit.sh", self.slurm_submit()),
        ];
        if self.demos.is_none() {
            files.insert(0, ("expert.sbatch", self.slurm_expert()));
        }
        write_all(&self.dir, &files)
    }

    /// Writes the Kubernetes Jobs and `submit-k8s.sh` into `DIR`; returns the paths written.
    pub fn write_k8s(&self, image: &str, claim: &str) -> std::io::Result<Vec<PathBuf>> {
        let invalid =
            |e: PlanError| std::io::Error::new(std::io::ErrorKind::InvalidInput, e.to_string());
        let jobs = self.k8s_jobs(image, claim).map_err(invalid)?;
        let names: Vec<String> = jobs.iter().map(|(f, _)| f.clone()).collect();
        let mut files: Vec<(&str, Result<String, PlanError>)> = jobs
            .iter()
            .map(|(f, t)| (f.as_str(), Ok(t.clone())))
            .collect();
        files.push(("submit-k8s.sh", self.k8s_submit(&names)));
        write_all(&self.dir, &files)
    }
}

fn write_all(
    dir: &Path,
    files: &[(&str, Result<String, PlanError>)],
) -> std::io::Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir.join("logs"))?;
    let mut out = Vec::new();
    for (name, text) in files {
        let text = text
            .as_ref()
            .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidInput, e.to_string()))?;
        let p = dir.join(name);
        std::fs::write(&p, text)?;
        #[cfg(unix)]
        if name.ends_with(".sh") || name.ends_with(".sbatch") {
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o755))?;
        }
        out.push(p);
    }
    Ok(out)
}

fn path_str(p: &Path) -> Result<&str, PlanError> {
    p.to_str()
        .ok_or_else(|| PlanError::Unquotable(p.display().to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plan() -> SweepPlan {
        SweepPlan {
            experiment: "comparison".into(),
            learner: "/opt/learner".into(),
            dir: "/shared/sweep one".into(),
            shards: 4,
            parallel: 1,
            args: vec![
                "--seeds".into(),
                "4".into(),
                "--iterations".into(),
                "5".into(),
            ],
            demos: None,
            partition: Some("cpu".into()),
            time: Some("00:30:00".into()),
            cpus: 1,
        }
    }

    #[test]
    fn slurm_scripts_chain_expert_array_merge() {
        let p = plan();
        p.validate().unwrap();
        let e = p.slurm_expert().unwrap();
        assert!(
            e.contains("--expert-only --out '/shared/sweep one/expert'"),
            "{e}"
        );
        assert!(
            e.contains("#SBATCH --partition=cpu\n#SBATCH --time=00:30:00\n"),
            "{e}"
        );
        let s = p.slurm_shards().unwrap();
        assert!(s.contains("#SBATCH --array=1-4%1\n"), "{s}");
        assert!(s.contains("K=$SLURM_ARRAY_TASK_ID\nN=4\n"), "{s}");
        assert!(
            s.contains(
                "/opt/learner experiment comparison --seeds 4 --iterations 5 --threads 1 \
                        --demos '/shared/sweep one/expert/demos.npz' --shard \"$K/$N\""
            ),
            "{s}"
        );
        assert!(s.contains("OUT='/shared/sweep one'/shard_${K}\n"), "{s}");
        assert!(
            s.contains("if ! mv -T \"$TMP\" \"$OUT\" 2>/dev/null; then\n"),
            "{s}"
        );
        let m = p.slurm_merge().unwrap();
        assert!(
            m.contains(
                "merge '/shared/sweep one/shard_1' '/shared/sweep one/shard_2' \
                        '/shared/sweep one/shard_3' '/shared/sweep one/shard_4' --out \"$TMP\"\n"
            ) && m.contains("OUT='/shared/sweep one'/merged\n")
                && m.contains("mv -T \"$TMP\" \"$OUT\"\n"),
            "{m}"
        );
        let sub = p.slurm_submit().unwrap();
        assert!(sub.contains("--dependency=afterok:$EXPERT '/shared/sweep one/shards.sbatch'"));
        assert!(sub.contains("--dependency=afterok:$SHARDS '/shared/sweep one/merge.sbatch'"));
    }

    #[test]
    fn given_demos_drop_the_expert_job() {
        let mut p = plan();
        p.demos = Some("/data/demos.npz".into());
        let sub = p.slurm_submit().unwrap();
        assert!(!sub.contains("EXPERT"), "{sub}");
        assert!(p
            .slurm_shards()
            .unwrap()
            .contains("--demos /data/demos.npz"));
        let k = p.k8s_jobs("reg/learner:1", "sweep").unwrap();
        let files: Vec<&str> = k.iter().map(|(f, _)| f.as_str()).collect();
        assert_eq!(files, ["k8s-shards.yaml", "k8s-merge.yaml"]);
    }

    #[test]
    fn k8s_jobs_are_an_expert_an_indexed_job_and_a_merge_applied_in_turn() {
        let p = plan();
        let jobs = p.k8s_jobs("reg/learner:1", "sweep-pvc").unwrap();
        let files: Vec<String> = jobs.iter().map(|(f, _)| f.clone()).collect();
        assert_eq!(
            files,
            ["k8s-expert.yaml", "k8s-shards.yaml", "k8s-merge.yaml"]
        );
        for (_, k) in &jobs {
            assert_eq!(k.matches("kind: Job").count(), 1, "{k}");
            assert!(k.contains("image: reg/learner:1\n"), "{k}");
            assert!(k.contains("claimName: sweep-pvc}"), "{k}");
            assert!(k.contains("mountPath: \"/shared/sweep one\"}"), "{k}");
            assert!(
                !k.contains("/opt/learner"),
                "learner from the image's PATH: {k}"
            );
        }
        assert!(jobs[0].1.contains("name: comparison-expert\n"));
        assert!(jobs[0].1.contains(
            "learner experiment comparison --seeds 4 --iterations 5 \
                                    --threads 1 --expert-only --out '/shared/sweep one/expert'"
        ));
        let s = &jobs[1].1;
        assert!(
            s.contains("completionMode: Indexed\n  completions: 4\n  parallelism: 1\n"),
            "{s}"
        );
        assert!(s.contains("K=$((JOB_COMPLETION_INDEX + 1))"), "{s}");
        assert!(s.contains("--demos '/shared/sweep one/expert/demos.npz' --shard \"$K/$N\""));
        assert!(jobs[2]
            .1
            .contains("learner experiment merge '/shared/sweep one/shard_1'"));
        for bad in ["", "a b", "x\"y", "{}"] {
            assert_eq!(
                p.k8s_jobs(bad, "c").unwrap_err(),
                PlanError::K8sName(bad.into())
            );
            assert!(p.k8s_jobs("i", bad).is_err());
        }
        let sub = p.k8s_submit(&files).unwrap();
        let order: Vec<&str> = sub
            .lines()
            .filter(|l| l.starts_with("kubectl apply") || l.starts_with("wait_job "))
            .collect();
        assert_eq!(
            order,
            [
                "kubectl apply -f '/shared/sweep one/k8s-expert.yaml'",
                "wait_job comparison-expert",
                "kubectl apply -f '/shared/sweep one/k8s-shards.yaml'",
                "wait_job comparison-shards",
                "kubectl apply -f '/shared/sweep one/k8s-merge.yaml'",
                "wait_job comparison-merge",
            ]
        );
    }

    #[test]
    fn bad_plans_are_refused() {
        let mut p = plan();
        p.shards = 0;
        assert_eq!(p.validate(), Err(PlanError::NoShards));
        let mut p = plan();
        p.parallel = 0;
        assert_eq!(p.validate(), Err(PlanError::NoParallel));
        let mut p = plan();
        p.dir = "rel/dir".into();
        assert_eq!(p.validate(), Err(PlanError::Relative("rel/dir".into())));
        // Shards without bound: a merge command no shell could run.
        let mut p = plan();
        p.shards = 1_000_000;
        assert_eq!(p.validate(), Err(PlanError::TooManyShards(1_000_000)));
        p.shards = MAX_SHARDS;
        p.validate().unwrap();
        p.dir = format!("/{}", "d".repeat(2000)).into();
        assert!(matches!(p.validate(), Err(PlanError::MergeTooLong(n)) if n > MAX_COMMAND_BYTES));
        for t in ["1:00", "01:60:00", "aa:00:00", "01:5:00", ""] {
            assert!(check_time(t).is_err(), "{t}");
        }
        for t in ["00:30:00", "120:00:00"] {
            check_time(t).unwrap();
        }
    }

    /// The array task's script, run twice with a stand-in `learner` (and once after a killed
    /// run left its temporary folder), leaves one whole `shard_K` and no temporaries.
    #[cfg(unix)]
    #[test]
    fn a_shard_task_run_twice_leaves_one_whole_shard() {
        let dir = std::env::temp_dir().join(format!("scheduler-twice-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let stub = dir.join("learner");
        std::fs::write(
            &stub,
            "#!/bin/bash\nwhile [ $# -gt 0 ]; do case $1 in --out) o=$2;; --shard) k=$2;; esac; \
             shift; done\nmkdir -p \"$o\"\necho \"$k\" > \"$o/shard.json\"\necho x >> \"$o/runs\"\n",
        )
        .unwrap();
        let mut p = plan();
        p.learner = stub.clone();
        p.dir = dir.join("sweep dir");
        p.demos = Some("/data/demos.npz".into());
        p.write_slurm().unwrap();
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&stub, std::fs::Permissions::from_mode(0o755)).unwrap();
        std::fs::create_dir_all(p.dir.join(".shard_2.1.gone")).unwrap();
        for _ in 0..2 {
            let st = std::process::Command::new("bash")
                .arg(p.dir.join("shards.sbatch"))
                .env("SLURM_ARRAY_TASK_ID", "2")
                .status()
                .unwrap();
            assert!(st.success());
        }
        let shard = p.dir.join("shard_2");
        let mut files: Vec<String> = std::fs::read_dir(&shard)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        files.sort();
        assert_eq!(files, ["runs", "shard.json"]);
        assert_eq!(std::fs::read_to_string(shard.join("runs")).unwrap(), "x\n");
        assert_eq!(
            std::fs::read_to_string(shard.join("shard.json")).unwrap(),
            "2/4\n"
        );
        let temps: Vec<String> = std::fs::read_dir(&p.dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with(".shard_") && n != ".shard_2.1.gone")
            .collect();
        assert!(temps.is_empty(), "{temps:?}");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn quoting_survives_the_shell() {
        assert_eq!(quote("a b").unwrap(), "'a b'");
        assert_eq!(quote("it's").unwrap(), r"'it'\''s'");
        assert_eq!(quote("/x/y-1.npz").unwrap(), "/x/y-1.npz");
        assert!(quote("a\nb").is_err());
    }
}
