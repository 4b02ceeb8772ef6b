//! One serve run once its ports exist: publish, assemble the episodes of the sample stream,
//! update when a batch is in, report while idle, and at the end the summary (docs/design.md
//! §3.6).

use std::io::Write;
use std::time::{Duration, Instant};

use gps::policy::lin_gauss::LinGaussPolicy;
use imitation::controller::to_gain_table;
use imitation::rollout::Episode;
use ur5_shared::{GainTable, StepSample};

use super::learner::{Publication, Run};
use super::ports::Ports;
use super::task_check::{Reference, TaskCheck};
use super::{
    Assembled, Assembler, Batch, Counts, ServeError, ServeExit, ServeLearner, ServeSummary,
};
use crate::io::learned::LearnedEvent;
use crate::io::table::save_table;
use crate::io::IoError;
use crate::progress::Progress;

/// Runs the serve loop on `ports` until the learning is done or SIGINT/SIGTERM.
pub(super) fn serve_with_ports<L: ServeLearner>(
    ports: &Ports<GainTable>,
    run: Run<L>,
    progress: &mut impl FnMut(&L::Log),
) -> Result<ServeSummary<L::Log>, ServeError> {
    let mut session = Session::start(ports, run)?;
    let exit = session.serve(progress)?;
    session.finish(exit)
}

/// `v` or `v (publication e)` for the log.
fn publication(version: u64, epoch: u32) -> String {
    if epoch == 0 {
        version.to_string()
    } else {
        format!("{version} (publication {epoch})")
    }
}

/// What one pass over the received samples ended with.
enum Drained {
    /// No sample was waiting.
    Nothing,
    /// Samples were handled; more may come.
    Some,
    /// The run is over.
    Exit(ServeExit),
}

/// The state of a serve run between samples.
struct Session<'p, L: ServeLearner> {
    ports: &'p Ports<GainTable>,
    run: Run<L>,
    /// The version this run started from.
    start_version: u64,
    /// Horizon T (steps).
    t_len: usize,
    asm: Assembler,
    /// The current version's publications and the one whose episodes are collected.
    publications: Vec<Publication>,
    at: usize,
    /// The current publication's episodes.
    batch: Batch,
    /// The version's episodes of its earlier publications: noisy goal-major, one evaluation
    /// per goal.
    noisy: Vec<Episode>,
    evals: Vec<Episode>,
    check: TaskCheck,
    counts: Counts,
    log: Vec<L::Log>,
    /// The best controller so far (when the learner's policy is one) and the task cost of its
    /// noise-free episodes (their mean with several goals).
    best: Option<(Option<LinGaussPolicy>, f64)>,
    /// The last table is published: the run ends when the controller runs it.
    finishing: bool,
    /// The first sample of the current version (the time an update waited).
    version_started: Option<Instant>,
    /// The newer (version, epoch) last reported.
    newer_reported: (u64, u32),
    /// The recorded files of the batch's episodes (`episodes/learned.jsonl`).
    used_noisy: Vec<String>,
    used_evals: Vec<String>,
    bar: Progress,
}

impl<'p, L: ServeLearner> Session<'p, L> {
    /// Saves and publishes the start version, notes a resume and says what it waits for.
    fn start(ports: &'p Ports<GainTable>, mut run: Run<L>) -> Result<Self, ServeError> {
        let start_version = run.learner.version();
        let publications = run.save_current()?;
        ports.publish_any(&publications[0].table)?;
        if let Some(from) = &run.opts.resume {
            let same =
                |p: &std::path::Path| std::fs::canonicalize(p).unwrap_or_else(|_| p.to_owned());
            run.note(&LearnedEvent::Resumed {
                iteration: run.learner.iteration(),
                same_folder: same(from) == same(&run.opts.out),
            })?;
        }
        let (n, t_len) = (run.learner.samples(), run.learner.task().horizon);
        let goals = run.learner.goal_tasks().len();
        eprintln!(
            "learner serve ({}): prefix `{}`, published {} table version {start_version}{}; waiting for {n} noisy + 1 noise-free episodes of T = {t_len} per version{}",
            L::ALGO,
            run.opts.prefix,
            match publications[0].table {
                super::ports::AnyTable::Gain(_) => "gain",
                super::ports::AnyTable::Policy(_) => "policy",
            },
            if run.opts.resume.is_some() {
                format!(" (resumed; publication {} of it)", run.epoch)
            } else {
                String::new()
            },
            if goals > 1 {
                format!(" and goal ({goals} goals, a table for each goal's noisy episodes and one for its evaluation)")
            } else {
                String::new()
            },
        );
        if !L::PROGRESS_HEADER.is_empty() {
            eprintln!("{}", L::PROGRESS_HEADER);
        }
        // The seed is checked on the first version this learner publishes itself: the
        // controller may have run the start version (a resumed one, or one it already had)
        // for longer, with later episodes' noise.
        let mut check = TaskCheck::default();
        check.seed_from_version = start_version + 1;
        let bar = Progress::new(
            run.learner
                .planned_iterations()
                .saturating_sub(run.learner.iteration()) as u64,
            "iterations",
        );
        Ok(Self {
            ports,
            start_version,
            t_len,
            asm: Assembler::new(t_len, run.learner.task().layout()),
            publications,
            at: 0,
            batch: Batch {
                noisy: Vec::with_capacity(n),
                eval: None,
            },
            noisy: Vec::with_capacity(n * goals),
            evals: Vec::with_capacity(goals),
            check,
            counts: Counts::default(),
            log: Vec::new(),
            best: None,
            finishing: run.learner.done(),
            version_started: None,
            newer_reported: (0, 0),
            used_noisy: Vec::with_capacity(n * goals),
            used_evals: Vec::with_capacity(goals),
            bar,
            run,
        })
    }

    /// Handles samples as they come; while none do, delivers the table to a controller that
    /// connected late, stops with the controller's message if it stopped (§3.12) and says
    /// every `wait_report_s` that it waits.
    fn serve(&mut self, progress: &mut impl FnMut(&L::Log)) -> Result<ServeExit, ServeError> {
        let report = Duration::from_secs_f64(self.run.opts.wait_report_s);
        let idle = Duration::from_micros(self.run.opts.idle_sleep_us.max(1));
        let mut last_sample = Instant::now();
        let mut last_report = Instant::now();
        loop {
            match self.drain(progress)? {
                Drained::Exit(exit) => return Ok(exit),
                Drained::Some => {
                    last_sample = Instant::now();
                    continue;
                }
                Drained::Nothing => {}
            }
            self.ports.update_connections();
            self.ports.status.check_controller()?;
            if last_sample.elapsed() >= report && last_report.elapsed() >= report {
                last_report = Instant::now();
                self.report_waiting(last_sample.elapsed());
            }
            if self.ports.node.wait(idle).is_err() {
                return Ok(ServeExit::Stopped);
            }
        }
    }

    /// Handles every sample waiting.
    fn drain(&mut self, progress: &mut impl FnMut(&L::Log)) -> Result<Drained, ServeError> {
        let mut got = Drained::Nothing;
        while let Some(sample) = self
            .ports
            .samples
            .receive()
            .map_err(|e| ServeError::Ipc(format!("receiving samples: {e:?}")))?
        {
            let s = *sample;
            drop(sample);
            got = Drained::Some;
            if let Some(exit) = self.on_sample(&s, progress)? {
                return Ok(Drained::Exit(exit));
            }
        }
        Ok(got)
    }

    /// Checks `s`, assembles it, handles the episodes it ends and updates when the batch is
    /// full.
    fn on_sample(
        &mut self,
        s: &StepSample,
        progress: &mut impl FnMut(&L::Log),
    ) -> Result<Option<ServeExit>, ServeError> {
        self.counts.samples += 1;
        self.check.sample(s, &self.run.learner)?;
        if (s.table_version, s.table_epoch) == (self.run.learner.version(), self.run.epoch)
            && self.version_started.is_none()
        {
            self.version_started = Some(Instant::now());
        }
        for a in self.asm.push(s) {
            if let Some(exit) = self.on_assembled(a)? {
                return Ok(Some(exit));
            }
        }
        let p = &self.publications[self.at];
        if self.batch.noisy.len() >= p.noisy && (self.batch.eval.is_some() || !p.eval) {
            self.next_publication(progress)?;
        }
        Ok(None)
    }

    /// The current publication's episodes are in: keeps them and publishes the version's next
    /// publication, or, after its last, updates.
    fn next_publication(&mut self, progress: &mut impl FnMut(&L::Log)) -> Result<(), ServeError> {
        self.noisy.append(&mut self.batch.noisy);
        self.evals.extend(self.batch.eval.take());
        self.at += 1;
        match self.publications.get(self.at) {
            Some(p) => {
                self.run.epoch = p.table.publication().1;
                self.ports.publish_any(&p.table)
            }
            None => self.update(progress),
        }
    }

    /// The reference the task checks hold episodes to: the current publication.
    fn reference(&self) -> Reference<'_> {
        Reference::of(
            &self.run.learner,
            &self.publications[self.at],
            self.publications.len(),
        )
    }

    /// Counts a discarded episode, or handles a complete one.
    fn on_assembled(&mut self, a: Assembled) -> Result<Option<ServeExit>, ServeError> {
        match a {
            Assembled::Complete {
                episode,
                version,
                epoch,
                ep,
            } => self.on_complete(ep, episode, version, epoch),
            Assembled::Partial { episode, have } => {
                self.counts.partial += 1;
                self.bar.println(&format!(
                    "learner serve: discarded episode {episode}: {have} of {} steps",
                    self.t_len
                ));
                self.check.partial(have, &self.run.learner)?;
                Ok(None)
            }
            Assembled::Mixed { episode } => {
                self.counts.mixed += 1;
                self.bar.println(&format!("learner serve: discarded episode {episode}: table version or noise flag changed inside it"));
                Ok(None)
            }
            Assembled::WrongDimensions { mismatch, .. } => Err(ServeError::Peer(mismatch)),
        }
    }

    /// Records and checks complete episode `ep` (`episode` of publication `epoch` of table
    /// `version`), then sorts it: older, newer, the sign that the last table runs, or one the
    /// batch takes or not.
    fn on_complete(
        &mut self,
        ep: Episode,
        episode: u64,
        version: u64,
        epoch: u32,
    ) -> Result<Option<ServeExit>, ServeError> {
        self.counts.episodes += 1;
        let file = self.run.record(&ep, episode, version, epoch)?;
        let tolerance = self.run.opts.task_tolerance;
        let mut check = std::mem::take(&mut self.check);
        let checked = check.episode(&ep, (version, epoch), &self.reference(), tolerance);
        self.check = check;
        checked?;
        let current = (self.run.learner.version(), self.run.epoch);
        // An earlier publication of the current version counts as an older version: its
        // episodes carry later noise keys than the ones this learner waits for.
        if (version, epoch) < current {
            self.counts.old_version += 1;
        } else if (version, epoch) > current {
            self.counts.newer_version += 1;
            if (version, epoch) != self.newer_reported {
                self.newer_reported = (version, epoch);
                self.bar.println(&format!(
                    "learner serve: the controller runs table version {}, newer than this learner's {}: \
                     another learner published it; restart this one with --resume <its out dir> to continue from there",
                    publication(version, epoch),
                    publication(current.0, current.1)
                ));
            }
        } else if self.finishing {
            // The controller took the last table: nothing more to learn.
            return Ok(Some(ServeExit::Done));
        } else {
            self.offer(ep, file);
        }
        Ok(None)
    }

    /// Offers an episode of the current version to the batch; remembers the file of one it
    /// takes.
    fn offer(&mut self, ep: Episode, file: Option<String>) {
        let noisy = ep.noisy;
        let p = &self.publications[self.at];
        // A publication that gives no evaluation (a gain table of several) takes none.
        if (noisy || p.eval) && self.batch.offer(ep, p.noisy) {
            self.counts.used += 1;
            match (noisy, file) {
                (true, Some(f)) => self.used_noisy.push(f),
                (false, Some(f)) => self.used_evals.push(f),
                (_, None) => {}
            }
        } else {
            self.counts.surplus += 1;
        }
    }

    /// Steps 2–6 on the version's episodes: notes the episodes used, learns, writes the CSV
    /// row, saves and publishes the next version.
    fn update(&mut self, progress: &mut impl FnMut(&L::Log)) -> Result<(), ServeError> {
        let run = &mut self.run;
        let evals = std::mem::take(&mut self.evals);
        let cost = evals.iter().map(Episode::task_cost).sum::<f64>() / evals.len() as f64;
        if self.best.as_ref().is_none_or(|(_, c)| cost < *c) {
            self.best = Some((run.learner.served_policy().cloned(), cost));
        }
        let waited = self
            .version_started
            .take()
            .map_or(0.0, |t0| t0.elapsed().as_secs_f64());
        // Before the update's checkpoint: the last line of a version counts.
        let mut used_evals = std::mem::take(&mut self.used_evals).into_iter();
        if let Some(eval) = used_evals.next() {
            run.note(&LearnedEvent::Learned {
                iteration: run.learner.iteration() + 1,
                version: run.learner.version(),
                noisy: std::mem::take(&mut self.used_noisy),
                eval,
                more_evals: used_evals.collect(),
            })?;
        }
        let entry = run.learner.learn_goals(&self.noisy, &evals, waited)?;
        self.noisy.clear();
        // The row before the checkpoint, as `learner train` writes them: a kill between the
        // two leaves a row that a resume from the previous checkpoint drops and writes again,
        // never a checkpoint without its row.
        let row = run.learner.csv_row(&entry)?;
        run.csv.write_all(row.as_bytes()).map_err(IoError::file(
            "writing the per-iteration log in",
            &run.opts.out,
        ))?;
        run.epoch = 0;
        self.publications = run.save_current()?;
        self.at = 0;
        self.ports.publish_any(&self.publications[0].table)?;
        self.bar.done_one(&L::progress_line(&entry));
        progress(&entry);
        self.log.push(entry);
        self.finishing = run.learner.done();
        if self.finishing {
            self.bar.println(&format!(
                "learner serve: learning done ({} iterations); published the last table, version {}; \
                 exiting once the controller runs it",
                run.learner.iteration(),
                run.learner.version()
            ));
        }
        Ok(())
    }

    /// Says that no sample came for `quiet`.
    fn report_waiting(&self, quiet: Duration) {
        let prefix = &self.run.opts.prefix;
        self.bar.println(&format!(
            "learner serve: waiting for episodes of table version {} on prefix `{prefix}`: no sample for {:.0} s \
             (is rt-controller running with --prefix {prefix}?)",
            self.run.learner.version(),
            quiet.as_secs_f64(),
        ));
    }

    /// Writes `best_table.npz` and finishes `run.mcap`; the summary.
    fn finish(self, exit: ServeExit) -> Result<ServeSummary<L::Log>, ServeError> {
        let Self {
            mut run,
            bar,
            best,
            log,
            counts,
            start_version,
            ..
        } = self;
        drop(bar);
        let out = run.opts.out.clone();
        if let Some((Some(pol), _)) = &best {
            save_table(
                &out.join("best_table.npz"),
                &to_gain_table(pol, run.learner.version()),
                run.learner.task().dt,
            )?;
        }
        if let Some(m) = run.mcap.take() {
            let c = m.finish()?;
            eprintln!(
                "learner serve: {} episodes and {} tables -> {}",
                c.episodes,
                c.tables,
                out.join("run.mcap").display()
            );
        }
        Ok(ServeSummary {
            command: "serve",
            algorithm: L::ALGO,
            exit_reason: exit,
            start_version,
            table_version: run.learner.version(),
            iterations: log.len(),
            eval_costs: log.iter().map(L::eval_cost).collect(),
            best_eval_cost: best.map(|(_, c)| c),
            log,
            counts,
            out,
        })
    }
}
