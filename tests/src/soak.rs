//! The soak's figures (`soak` binary): what the three processes' logs say
//! ([`LogCounts`]) and what the files of a `learner serve` run folder hold ([`scan_run`]).
//!
//! The scan reads every file the learner writes (docs/design.md §3.6 "Files") and checks:
//! - **corrupted**: every `.npz` loads with its own reader (episode, gain table, checkpoint),
//!   every `.json` parses, every CSV row has the header's number of fields and ends with a
//!   newline; a leftover temporary (`*.tmp`, `*.partial`, the atomic writes' names) is counted
//!   apart, it is not a file of the run;
//! - **mixed versions**: every recorded episode carries the version its name says, and its
//!   actions are the controller law (`ur5_shared::controller_action`) of that one table version
//!   (`tables/vNNNN.npz`) at every step, bit for bit: noise-free episodes with ε = 0, noisy
//!   ones with the noise of some episode k of that version (`Noise::new(seed, v, k)`,
//!   docs/design.md §3.4), found by search. An episode that mixed two tables, or whose table
//!   was replaced under the same version number, fails it;
//! - **commands outside the limits**: every executed action (`actions`, after the clamp) lies
//!   within the joint limits and at most velocity × dt from the joint angles of its step
//!   (`ur5_shared::safety::clamp_action`, the controller's default `[limits]`).

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use learner::io::checkpoint::load_checkpoint;
use learner::io::episode::load_episode;
use learner::io::table::load_table;
use serde::Serialize;
use ur5_shared::config::ArmLimits;
use ur5_shared::noise::Noise;
use ur5_shared::{controller_action, GainBounds, GainTable, DU, DX};

/// Noisy episodes per table version and noise-free ones per cycle: the controller's defaults,
/// which the soak runs (`noisy_episodes`, `eval_episodes`).
pub const CYCLE: (u64, u64) = (5, 1);
/// Largest episode index k of one version the noise search tries (the controller runs the
/// same version for as long as the learner is away: thousands of episodes would need a dead
/// learner for minutes, which the soak never allows).
pub const MAX_K: u64 = 20_000;
/// Relative slack on the per-step limit (the clamp computes q ± v·dt in f64).
const STEP_SLACK: f64 = 1e-12;

/// What the scan of a run folder found (module docs).
#[derive(Clone, Debug, Default, Serialize)]
pub struct Scan {
    /// Files read (every file under the folder).
    pub files: u64,
    /// Recorded episodes (`episodes/*.npz`).
    pub episode_files: u64,
    /// Of them, noise-free.
    pub noise_free: u64,
    /// Gain tables (`tables/vNNNN.npz`); the highest version.
    pub table_files: u64,
    pub max_version: u64,
    /// Rows of the per-iteration CSV (header aside).
    pub csv_rows: u64,
    /// Files that do not load or parse, CSV rows cut short (each counts once).
    pub corrupted: u64,
    /// Episodes not explained by one table version (module docs).
    pub mixed_versions: u64,
    /// Executed actions (one per step and joint) outside the limits.
    pub outside_limits: u64,
    /// Temporaries left by a kill during an atomic write.
    pub temporaries: u64,
    /// The first few problems, each naming its file.
    pub problems: Vec<String>,
}

impl Scan {
    fn problem(&mut self, msg: String) {
        if self.problems.len() < 20 {
            self.problems.push(msg);
        }
    }
}

/// Scans the run folder `out` of `learner serve` (module docs; the noise seed is each episode's own).
pub fn scan_run(out: &Path) -> Scan {
    let mut scan = Scan::default();
    let mut files = Vec::new();
    walk(out, &mut files);
    files.sort();
    let limits = ArmLimits::default();
    let bounds = GainBounds::default();
    let mut tables: HashMap<u64, Option<(Box<GainTable>, f64)>> = HashMap::new();
    let mut load_version = |v: u64| -> Option<(Box<GainTable>, f64)> {
        tables
            .entry(v)
            .or_insert_with(|| load_table(&learner::io::table::version_path(out, v), &bounds).ok())
            .as_ref()
            .map(|(t, dt)| (t.boxed_clone(), *dt))
    };
    for path in &files {
        scan.files += 1;
        let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
        let rel = path.strip_prefix(out).unwrap_or(path).display().to_string();
        if name.ends_with(".tmp") || name.ends_with(".partial") {
            scan.temporaries += 1;
            continue;
        }
        let in_dir = |d: &str| path.parent().and_then(|p| p.file_name()) == Some(d.as_ref());
        if name.ends_with(".npz") && in_dir("episodes") {
            scan.episode_files += 1;
            match load_episode(path) {
                Ok((ep, origin)) => {
                    if !ep.noisy {
                        scan.noise_free += 1;
                    }
                    let named = version_in_name(name);
                    let table = load_version(origin.table_version);
                    let why = if named != Some(origin.table_version) {
                        Some(format!(
                            "name says version {named:?}, file {}",
                            origin.table_version
                        ))
                    } else if let Some((table, _)) = &table {
                        explain(
                            &ep.x,
                            &ep.u_policy,
                            ep.noisy,
                            table,
                            origin.seed,
                            origin.table_version,
                        )
                        .err()
                    } else {
                        Some(format!("no readable table v{:04}", origin.table_version))
                    };
                    if let Some(why) = why {
                        scan.mixed_versions += 1;
                        scan.problem(format!("{rel}: not one table version: {why}"));
                    }
                    let dt = table.map_or(0.1, |(_, dt)| dt);
                    let out_of = outside_limits(&ep.x, &ep.u, &limits, dt);
                    if out_of > 0 {
                        scan.outside_limits += out_of;
                        scan.problem(format!("{rel}: {out_of} actions outside the limits"));
                    }
                }
                Err(e) => {
                    scan.corrupted += 1;
                    scan.problem(format!("{rel}: {e}"));
                }
            }
        } else if name.ends_with(".npz") && name != "checkpoint.npz" {
            if in_dir("tables") {
                scan.table_files += 1;
                if let Some(v) = name.strip_prefix('v').and_then(|n| n.strip_suffix(".npz")) {
                    scan.max_version = scan.max_version.max(v.parse().unwrap_or(0));
                }
            }
            if let Err(e) = load_table(path, &bounds) {
                scan.corrupted += 1;
                scan.problem(format!("{rel}: {e}"));
            }
        } else if name == "checkpoint.npz" {
            if let Err(e) = load_checkpoint(path) {
                scan.corrupted += 1;
                scan.problem(format!("{rel}: {e:#}"));
            }
        } else if name.ends_with(".json") {
            let ok = std::fs::read(path)
                .ok()
                .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok());
            if ok.is_none() {
                scan.corrupted += 1;
                scan.problem(format!("{rel}: not JSON"));
            }
        } else if name == learner::io::learned::LEARNED {
            // Only its last line may be cut by a kill (read_events leaves that one out).
            if let Err(e) = learner::io::learned::read_events(path.parent().unwrap_or(path)) {
                scan.corrupted += 1;
                scan.problem(format!("{rel}: {e:#}"));
            }
        } else if name.ends_with(".csv") {
            let (rows, bad) = check_csv(path);
            scan.csv_rows += rows;
            if bad > 0 {
                scan.corrupted += bad;
                scan.problem(format!("{rel}: {bad} rows cut short or unreadable"));
            }
        }
    }
    scan
}

fn walk(dir: &Path, files: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let p = e.path();
        if p.is_dir() {
            walk(&p, files);
        } else {
            files.push(p);
        }
    }
}

/// The version in an episode file's name `NNNNNN_eEPISODE_vVERSION.npz`.
fn version_in_name(name: &str) -> Option<u64> {
    name.strip_suffix(".npz")?.rsplit_once("_v")?.1.parse().ok()
}

/// (rows after the header, rows that are not complete): a complete row has the header's
/// number of fields and ends with a newline; a file that is not UTF-8 counts as one bad row.
fn check_csv(path: &Path) -> (u64, u64) {
    let Ok(text) = std::fs::read_to_string(path) else {
        return (0, 1);
    };
    let mut lines = text.split_inclusive('\n');
    let Some(header) = lines.next() else {
        return (0, 0);
    };
    let fields = header.trim_end().split(',').count();
    let (mut rows, mut bad) = (0, u64::from(!header.ends_with('\n')));
    for line in lines {
        rows += 1;
        if !line.ends_with('\n') || line.trim_end().split(',').count() != fields {
            bad += 1;
        }
    }
    (rows, bad)
}

/// Ok when `u_policy` ((T, dU)) is the law of `table` on the states `x` ((T, dX)) at every
/// step: with ε = 0 (noise-free) or the noise of one episode k of `version` (noisy).
pub fn explain(
    x: &[f64],
    u_policy: &[f64],
    noisy: bool,
    table: &GainTable,
    seed: u64,
    version: u64,
) -> Result<(), String> {
    let t_len = u_policy.len() / DU;
    let state = |t: usize| -> [f64; DX] { x[t * DX..(t + 1) * DX].try_into().expect("DX") };
    let matches = |noise: &mut dyn FnMut() -> [f64; DU], steps: usize| -> bool {
        (0..steps).all(|t| {
            let mut a = [0.0; DU];
            controller_action(table, t, &state(t), &noise(), &mut a).is_ok()
                && a.iter()
                    .zip(&u_policy[t * DU..(t + 1) * DU])
                    .all(|(p, q)| p.to_bits() == q.to_bits())
        })
    };
    if !noisy {
        return if matches(&mut || [0.0; DU], t_len) {
            Ok(())
        } else {
            Err(format!("noise-free actions are not v{version}'s law"))
        };
    }
    let (n, cycle) = (CYCLE.0, CYCLE.0 + CYCLE.1);
    for k in (0..MAX_K).filter(|k| k % cycle < n) {
        let mut noise = Noise::new(seed, version, k);
        if !matches(&mut || noise.next(), 1) {
            continue;
        }
        let mut noise = Noise::new(seed, version, k);
        return if matches(&mut || noise.next(), t_len) {
            Ok(())
        } else {
            Err(format!(
                "step 0 is v{version}'s law with the noise of episode {k}, later steps are not"
            ))
        };
    }
    Err(format!(
        "no noise of v{version}'s episodes 0..{MAX_K} gives its first action"
    ))
}

/// Executed actions `u` ((T, dU)) outside the joint limits or more than velocity × dt from the
/// joint angles of their step in `x` ((T, dX)).
pub fn outside_limits(x: &[f64], u: &[f64], limits: &ArmLimits, dt: f64) -> u64 {
    let mut n = 0;
    for (t, a) in u.chunks_exact(DU).enumerate() {
        for j in 0..DU {
            let q = x[t * DX + j];
            let step = limits.velocity[j] * dt * (1.0 + STEP_SLACK);
            let ok = a[j].is_finite()
                && a[j] >= limits.lower[j]
                && a[j] <= limits.upper[j]
                && (a[j] - q).abs() <= step;
            n += u64::from(!ok);
        }
    }
    n
}

/// What the processes' logs say, summed over every run of each (a killed process leaves no
/// summary, only its log lines).
#[derive(Clone, Debug, Default, Serialize)]
pub struct LogCounts {
    /// Controller: episodes done and aborted (`rt-controller: episode N done|ABORTED`).
    pub episodes_done: u64,
    pub episodes_aborted: u64,
    /// Controller: tables rejected (the last count each controller run reported).
    pub tables_rejected: u64,
    /// Learner: episodes discarded as partial and as mixed (`learner serve: discarded …`).
    pub discarded_partial: u64,
    pub discarded_mixed: u64,
    /// Learner: runs that started from a checkpoint (`(resumed)` on their first line).
    pub learner_resumes: u64,
}

impl LogCounts {
    /// Adds one controller run's log.
    pub fn controller(&mut self, log: &str) {
        let mut rejected = 0;
        for l in log.lines() {
            let Some(rest) = l.strip_prefix("rt-controller: episode ") else {
                continue;
            };
            if rest.contains(" done (") {
                self.episodes_done += 1;
            } else if rest.contains(" ABORTED (") {
                self.episodes_aborted += 1;
            }
            if let Some(r) = rest.split_once(", rejected ").and_then(|(_, r)| {
                r.split(|c: char| !c.is_ascii_digit())
                    .next()?
                    .parse::<u64>()
                    .ok()
            }) {
                rejected = r;
            }
        }
        self.tables_rejected += rejected;
    }

    /// Adds one learner run's log.
    pub fn learner(&mut self, log: &str) {
        for l in log.lines() {
            if let Some(rest) = l.strip_prefix("learner serve: discarded episode ") {
                if rest.contains("steps") {
                    self.discarded_partial += 1;
                } else {
                    self.discarded_mixed += 1;
                }
            }
            if l.starts_with("learner serve") && l.contains("(resumed)") {
                self.learner_resumes += 1;
            }
        }
    }
}
