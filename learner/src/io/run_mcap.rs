//! A recorded run as one MCAP file (docs/design.md §4.14), for Foxglove, Rerun and the `mcap`
//! tools: its recorded episodes (`RUN/episodes/*.npz`, in arrival order) laid end to end on one
//! time line, and its gain tables (`tables/vNNNN.npz` of `learner serve`, else
//! `iter_NNN_table.npz` of `learner train`). Written after the fact from a run folder
//! ([`write_run_mcap`], `learner dataset export --format mcap`) or as the run goes, episode by
//! episode ([`RunMcap`], `learner serve --mcap`): the same code, the same messages.
//!
//! Every message is JSON (`message_encoding` `json`) with a JSON Schema (`encoding`
//! `jsonschema`), which Foxglove decodes without plug-ins. Log time (= publish time, ns): the
//! episode's start plus t·dt; episode k starts where episode k − 1 ended (T·dt later), the
//! first at 0.
//!
//! | topic | schema | one message per | fields |
//! |---|---|---|---|
//! | `/joint_states` | `sensor_msgs/JointState` (its fields, in JSON) | step | `header` (`stamp` {`sec`, `nsec`}, `frame_id` `base`), `name` (URDF names of the active joints), `position` (rad), `velocity` (rad/s), `effort` (empty: not measured) |
//! | `/state` | `ur5.State` | step | `episode`, `table_version`, `noisy`, `t`, `q`, `qd` (rad, rad/s; n each), `ee_minus_goal` (m), `ee_vel` (m/s); a pose task: `point0_minus_target` … `point2_minus_target` (m), `point0_vel` … `point2_vel` (m/s) instead of the last two |
//! | `/action` | `ur5.Action` | step | `episode`, `table_version`, `t`, `executed` (after the clamp; the arm ran it), `policy` (the controller law's); dU each |
//! | `/fault` | `ur5.Fault` | step where the clamp changed the action | `episode`, `table_version`, `t`, `kind` (`action_clamped`), `policy`, `executed` |
//! | `/episode` | `ur5.Episode` | episode, at its last step | `episode`, `table_version`, `table_epoch`, `noisy`, `task_cost`, `final_distance_m`, a pose task's `final_orientation_error_deg`, `file` |
//! | `/table` | `ur5.GainTable` | table publication, when its first episode starts (at the end if it ran none) | `version`, `epoch` (the publication: a resumed learner publishes its version again with the next), `checksum` (XXH3-64, hex), `horizon`, `file` |
//!
//! The schemas give the sizes of the run's layout (`ur5_shared::StateLayout`, [`RunMcap::create`]):
//! one file holds the episodes of one task, and an episode of another layout is refused, naming
//! both. A three-joint run's file is what it was before six-joint tasks, byte for byte.
//!
//! Faults the controller reports (aborted episodes, safety holds) are not in a run folder
//! (incomplete episodes are not recorded), so `/fault` holds only the clamp's interventions.

use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use super::IoError;
use serde_json::json;
use ur5_shared::config::TaskConfig;
use ur5_shared::layout::{Part, StateLayout};

use imitation::rollout::Episode;

use super::episode::{episode_files, load_episode_task, recorded_episodes, EpisodeOrigin};
use super::table::load_stored;

/// What [`write_run_mcap`] wrote: messages per topic.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct McapCounts {
    /// Topic → messages.
    pub messages: BTreeMap<String, u64>,
    /// Episodes written.
    pub episodes: usize,
    /// Tables written.
    pub tables: usize,
}

/// The state's fields of `/state` after `q` and `qd`: the point parts of `layout`, named
/// `ee_minus_goal` and `ee_vel` for one tool point (the state names' convention).
fn point_fields(layout: &StateLayout) -> Vec<(String, std::ops::Range<usize>)> {
    layout
        .parts()
        .into_iter()
        .filter_map(|(part, range)| {
            let name = match part {
                Part::JointAngles | Part::JointVelocities => return None,
                Part::PointMinusTarget(_) if layout.tool_points() == 1 => "ee_minus_goal".into(),
                Part::PointVelocity(_) if layout.tool_points() == 1 => "ee_vel".into(),
                p => p.name(),
            };
            Some((name, range))
        })
        .collect()
}

/// The topics, their schema names and JSON Schemas, sized for `layout`.
fn channels(layout: &StateLayout) -> Vec<(&'static str, &'static str, serde_json::Value)> {
    let (n, du) = (layout.joints(), layout.du());
    let num = json!({"type": "number"});
    let int = json!({"type": "integer"});
    let vec = |n: usize| json!({"type": "array", "items": {"type": "number"}, "minItems": n, "maxItems": n});
    vec![
        (
            "/joint_states",
            "sensor_msgs/JointState",
            json!({"type": "object", "properties": {
                "header": {"type": "object", "properties": {
                    "stamp": {"type": "object", "properties": {"sec": int, "nsec": int}},
                    "frame_id": {"type": "string"}}},
                "name": {"type": "array", "items": {"type": "string"}},
                "position": {"type": "array", "items": num},
                "velocity": {"type": "array", "items": num},
                "effort": {"type": "array", "items": num}}}),
        ),
        ("/state", "ur5.State", {
            let mut state = json!({"type": "object", "properties": {
                    "episode": int, "table_version": int, "noisy": {"type": "boolean"}, "t": int,
                    "q": vec(n), "qd": vec(n)}});
            for (name, _) in point_fields(layout) {
                state["properties"][name] = vec(3);
            }
            state
        }),
        (
            "/action",
            "ur5.Action",
            json!({"type": "object", "properties": {
                "episode": int, "table_version": int, "t": int,
                "executed": vec(du), "policy": vec(du)}}),
        ),
        (
            "/fault",
            "ur5.Fault",
            json!({"type": "object", "properties": {
                "episode": int, "table_version": int, "t": int, "kind": {"type": "string"},
                "executed": vec(du), "policy": vec(du)}}),
        ),
        ("/episode", "ur5.Episode", {
            let mut episode = json!({"type": "object", "properties": {
                    "episode": int, "table_version": int, "table_epoch": int,
                    "noisy": {"type": "boolean"}, "task_cost": num, "final_distance_m": num, "file": {"type": "string"}}});
            if layout.tool_points() == 3 {
                episode["properties"]["final_orientation_error_deg"] = num.clone();
            }
            episode
        }),
        (
            "/table",
            "ur5.GainTable",
            json!({"type": "object", "properties": {
                "version": int, "epoch": int, "checksum": {"type": "string"}, "horizon": int,
                "file": {"type": "string"}}}),
        ),
    ]
}

/// The gain-table files of `run`: `tables/vNNNN.npz`, else `iter_NNN_table.npz`, by version.
fn table_files(run: &Path) -> Result<Vec<PathBuf>, IoError> {
    let list = |dir: &Path, keep: &dyn Fn(&str) -> bool| -> Result<Vec<PathBuf>, IoError> {
        let mut f = Vec::new();
        if let Ok(entries) = std::fs::read_dir(dir) {
            for e in entries {
                let p = e.map_err(IoError::file("reading", dir))?.path();
                if p.file_name().and_then(|n| n.to_str()).is_some_and(keep) {
                    f.push(p);
                }
            }
        }
        f.sort();
        Ok(f)
    };
    let served = list(&run.join("tables"), &|n| {
        n.starts_with('v') && n.ends_with(".npz")
    })?;
    if !served.is_empty() {
        return Ok(served);
    }
    list(run, &|n| {
        n.starts_with("iter_") && n.ends_with("_table.npz")
    })
}

/// A gain table as `/table` tells it.
#[derive(Clone, Debug, PartialEq)]
pub struct TableInfo {
    /// Its version.
    pub version: u64,
    /// Its publication ([`ur5_shared::GainTable::epoch`]: a resumed `learner serve` publishes
    /// its version again with the next epoch).
    pub epoch: u32,
    /// XXH3-64 checksum.
    pub checksum: u64,
    /// T.
    pub horizon: u64,
    /// Its file.
    pub file: PathBuf,
}

impl TableInfo {
    /// The table stored in `file`.
    pub fn load(file: &Path) -> Result<Self, IoError> {
        let t = load_stored(file)?;
        Ok(Self {
            version: t.version,
            epoch: t.epoch,
            checksum: t.checksum,
            horizon: t.arrays[0].1[0],
            file: file.to_owned(),
        })
    }

    fn message(&self) -> serde_json::Value {
        json!({"version": self.version, "epoch": self.epoch,
               "checksum": format!("{:#018x}", self.checksum),
               "horizon": self.horizon, "file": self.file.display().to_string()})
    }
}

/// Bytes [`RunMcap`] buffers: more than the chunk of an episode of T = 500 steps (≈ 0.9 KB of
/// JSON per step over the four per-step topics; measured ≈ 22 KB for T = 20), so that a chunk
/// reaches the file in one write when its episode is complete.
const EPISODE_BUFFER: usize = 1 << 20;

/// An MCAP file written as the run goes (`learner serve --mcap`; module docs): one chunk per
/// episode, kept in memory and written out (chunk finished, buffer flushed) when the episode
/// is complete, so a killed process leaves a file whose chunks hold every episode up to the
/// last complete one; only the summary section and footer, which [`RunMcap::finish`] (or
/// dropping it) writes, are missing. (A kill during that one write can leave the start of the
/// next chunk: streaming readers then also return the steps in it, never its `/episode`
/// message, which is the episode's last.) Readers that stream the file from its start read
/// such a file up to where it ends (docs/design.md §4.14): the `mcap` crate's `MessageStream`
/// with `Options::IgnoreEndMagic` (messages, then an error at the cut), the Python reader's
/// `NonSeekingReader` (messages, then `EndOfFile`); readers that start from the summary (the
/// Python `SeekingReader` that `make_reader` picks for a file) refuse it.
pub struct RunMcap {
    w: mcap::Writer<BufWriter<std::fs::File>>,
    /// The run's layout: every episode's.
    layout: StateLayout,
    ids: BTreeMap<&'static str, u16>,
    seq: u32,
    /// Where the next episode starts on the time line (s).
    start: f64,
    /// Tables announced and not yet in force, by version.
    pending: Vec<TableInfo>,
    /// The newest publication announced: (version, epoch).
    last_table: (u64, u32),
    counts: McapCounts,
}

impl RunMcap {
    /// Creates `out` (and its folder) with the header, the schemas and the channels, sized
    /// for the run's `layout`.
    pub fn create(out: &Path, layout: StateLayout) -> Result<Self, IoError> {
        if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
            super::create_dir(dir)?;
        }
        let file = std::fs::File::create(out).map_err(IoError::file("creating", out))?;
        let mut w = mcap::WriteOptions::new()
            .compression(None)
            .profile("")
            .library(concat!("learner ", env!("CARGO_PKG_VERSION")))
            // Chunks end where `episode` ends them.
            .chunk_size(None)
            // An episode's chunk stays in memory until `episode` writes it out whole.
            .create(BufWriter::with_capacity(EPISODE_BUFFER, file))?;
        let mut ids = BTreeMap::new();
        for (topic, name, schema) in channels(&layout) {
            let s = w.add_schema(name, "jsonschema", &serde_json::to_vec(&schema)?)?;
            let c = w.add_channel(s, topic, "json", &BTreeMap::new())?;
            ids.insert(topic, c);
        }
        w.flush()?;
        Ok(Self {
            w,
            layout,
            ids,
            seq: 0,
            start: 0.0,
            pending: Vec::new(),
            last_table: (0, 0),
            counts: McapCounts::default(),
        })
    }

    fn put(&mut self, topic: &'static str, ns: u64, msg: serde_json::Value) -> Result<(), IoError> {
        self.seq += 1;
        *self.counts.messages.entry(topic.to_owned()).or_default() += 1;
        let header = mcap::records::MessageHeader {
            channel_id: self.ids[topic],
            sequence: self.seq,
            log_time: ns,
            publish_time: ns,
        };
        self.w
            .write_to_known_channel(&header, &serde_json::to_vec(&msg)?)
            .map_err(IoError::from)
    }

    /// Announces a table: its `/table` message comes when its first episode starts (or at the
    /// end). A publication not newer than the last one announced, by (version, epoch), is
    /// ignored; a resumed learner's new publication of its version is announced.
    pub fn table(&mut self, t: TableInfo) {
        if (t.version, t.epoch) > self.last_table {
            self.last_table = (t.version, t.epoch);
            self.counts.tables += 1;
            self.pending.push(t);
        }
    }

    /// Writes the episode recorded as `path` (of the run's `task`: its control period, and a
    /// pose task's targets for the orientation error) and ends its chunk. An episode of
    /// another layout than the file's is refused, naming both.
    pub fn episode(
        &mut self,
        path: &Path,
        ep: &Episode,
        origin: &EpisodeOrigin,
        task: &TaskConfig,
    ) -> Result<(), IoError> {
        self.layout
            .check_dims("the episode", ep.layout.dx(), ep.layout.du())
            .map_err(|e| IoError::from(e).at("writing to the MCAP log the episode", path))?;
        let dt = task.dt;
        let start = self.start;
        let ns = |t: usize| ((start + t as f64 * dt) * 1e9).round() as u64;
        let v = origin.table_version;
        // Publications up to this episode's come into force now.
        let pubn = (v, origin.table_epoch);
        while self
            .pending
            .first()
            .is_some_and(|t| (t.version, t.epoch) <= pubn)
        {
            let t = self.pending.remove(0);
            self.put("/table", ns(0), t.message())?;
        }
        let (e, noisy) = (origin.episode, ep.noisy);
        let layout = ep.layout;
        let (q, qd, du) = (layout.q(), layout.qd(), layout.du());
        let (joints, points) = (layout.joint_urdf_names(), point_fields(&layout));
        for t in 0..ep.horizon() {
            let s = ep.state(t);
            let (sec, nsec) = (ns(t) / 1_000_000_000, ns(t) % 1_000_000_000);
            self.put(
                "/joint_states",
                ns(t),
                json!({
                "header": {"stamp": {"sec": sec, "nsec": nsec}, "frame_id": "base"},
                "name": &joints, "position": &s[q.clone()], "velocity": &s[qd.clone()],
                "effort": [] }),
            )?;
            let mut state = json!({
                "episode": e, "table_version": v, "noisy": noisy, "t": t,
                "q": &s[q.clone()], "qd": &s[qd.clone()]});
            for (name, range) in &points {
                state[name] = json!(&s[range.clone()]);
            }
            self.put("/state", ns(t), state)?;
            let executed = &ep.u[t * du..(t + 1) * du];
            let policy = &ep.u_policy[t * du..(t + 1) * du];
            self.put(
                "/action",
                ns(t),
                json!({
                "episode": e, "table_version": v, "t": t, "executed": executed, "policy": policy}),
            )?;
            if executed != policy {
                self.put(
                    "/fault",
                    ns(t),
                    json!({
                    "episode": e, "table_version": v, "t": t, "kind": "action_clamped",
                    "executed": executed, "policy": policy}),
                )?;
            }
        }
        let last = ep.horizon() - 1;
        let mut summary = json!({
            "episode": e, "table_version": v, "table_epoch": origin.table_epoch,
            "noisy": noisy, "task_cost": ep.task_cost(),
            "final_distance_m": ep.final_distance(), "file": path.display().to_string()});
        if let Some(o) = ep.final_orientation_error(&task.targets()) {
            summary["final_orientation_error_deg"] = json!(o.to_degrees());
        }
        self.put("/episode", ns(last), summary)?;
        self.start += ep.horizon() as f64 * dt;
        self.counts.episodes += 1;
        // The chunk is complete on disk: a kill from here on loses nothing of it.
        self.w.flush()?;
        Ok(())
    }

    /// Writes what the run folder `run` holds so far: its tables ([`table_files`]) and its
    /// recorded episodes in arrival order (a whole run exported, or a resumed served run's
    /// earlier part).
    pub fn add_run(&mut self, run: &Path) -> Result<(), IoError> {
        for f in table_files(run)? {
            self.table(TableInfo::load(&f)?);
        }
        for (path, ep, origin) in recorded_episodes(&run.join("episodes"))? {
            let task = load_episode_task(&path)?;
            self.episode(&path, &ep, &origin, &task)?;
        }
        Ok(())
    }

    /// The tables that ran no episode (at the end of the time line), then the summary
    /// section and footer.
    pub fn finish(mut self) -> Result<McapCounts, IoError> {
        let end = (self.start * 1e9).round() as u64;
        for t in std::mem::take(&mut self.pending) {
            self.put("/table", end, t.message())?;
        }
        self.w.finish()?;
        Ok(std::mem::take(&mut self.counts))
    }
}

/// Writes the run in `run` (its `episodes/` and tables) to the MCAP file `out` (module docs).
///
/// The file's layout is the first episode's (three joints and a point if there is none).
pub fn write_run_mcap(run: &Path, out: &Path) -> Result<McapCounts, IoError> {
    let layout = match episode_files(&run.join("episodes"))?.first() {
        Some(f) => load_episode_task(f)?.layout(),
        None => StateLayout::REACH3,
    };
    let mut m = RunMcap::create(out, layout)?;
    m.add_run(run)?;
    if m.counts.episodes == 0 {
        drop(m);
        std::fs::remove_file(out).ok();
        return Err(IoError::content(
            run,
            "no recorded episodes (episodes/*.npz; `learner serve` records them, `learner \
             train` with --record-episodes)",
        ));
    }
    m.finish()
}
