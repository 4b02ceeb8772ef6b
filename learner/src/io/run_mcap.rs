//! A recorded run as one MCAP file (docs/design.md §4.14), for Foxglove, Rerun and the `mcap`
//! tools: its recorded episodes (`RUN/episodes/*.npz`, in arrival order) laid end to end on one
//! time line, and its gain tables (`tables/vNNNN.npz` of `learner serve`, else
//! `iter_NNN_table.npz` of `learner train`).
//!
//! Every message is JSON (`message_encoding` `json`) with a JSON Schema (`encoding`
//! `jsonschema`), which Foxglove decodes without plug-ins. Log time (= publish time, ns): the
//! episode's start plus t·dt; episode k starts where episode k − 1 ended (T·dt later), the
//! first at 0.
//!
//! | topic | schema | one message per | fields |
//! |---|---|---|---|
//! | `/joint_states` | `sensor_msgs/JointState` (its fields, in JSON) | step | `header` (`stamp` {`sec`, `nsec`}, `frame_id` `base`), `name` (URDF joint names), `position` (rad), `velocity` (rad/s), `effort` (empty: not measured) |
//! | `/state` | `ur5.State` | step | `episode`, `table_version`, `noisy`, `t`, `q`, `qd` (rad, rad/s), `ee_minus_goal` (m), `ee_vel` (m/s) |
//! | `/action` | `ur5.Action` | step | `episode`, `table_version`, `t`, `executed` (after the clamp; the arm ran it), `policy` (the controller law's) |
//! | `/fault` | `ur5.Fault` | step where the clamp changed the action | `episode`, `table_version`, `t`, `kind` (`action_clamped`), `policy`, `executed` |
//! | `/episode` | `ur5.Episode` | episode, at its last step | `episode`, `table_version`, `noisy`, `task_cost`, `final_distance_m`, `file` |
//! | `/table` | `ur5.GainTable` | table version, when its first episode starts (at the end if it ran none) | `version`, `checksum` (XXH3-64, hex), `horizon`, `file` |
//!
//! Faults the controller reports (aborted episodes, safety holds) are not in a run folder
//! (incomplete episodes are not recorded), so `/fault` holds only the clamp's interventions.

use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use anyhow::Context;
use serde_json::json;
use ur5_shared::layout::{ACTIVE_JOINTS, DU, DX};

use super::episode::{load_episode_task, recorded_episodes};
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

/// The topics, their schema names and JSON Schemas.
fn channels() -> Vec<(&'static str, &'static str, serde_json::Value)> {
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
        (
            "/state",
            "ur5.State",
            json!({"type": "object", "properties": {
                "episode": int, "table_version": int, "noisy": {"type": "boolean"}, "t": int,
                "q": vec(3), "qd": vec(3), "ee_minus_goal": vec(3), "ee_vel": vec(3)}}),
        ),
        (
            "/action",
            "ur5.Action",
            json!({"type": "object", "properties": {
                "episode": int, "table_version": int, "t": int,
                "executed": vec(DU), "policy": vec(DU)}}),
        ),
        (
            "/fault",
            "ur5.Fault",
            json!({"type": "object", "properties": {
                "episode": int, "table_version": int, "t": int, "kind": {"type": "string"},
                "executed": vec(DU), "policy": vec(DU)}}),
        ),
        (
            "/episode",
            "ur5.Episode",
            json!({"type": "object", "properties": {
                "episode": int, "table_version": int, "noisy": {"type": "boolean"},
                "task_cost": num, "final_distance_m": num, "file": {"type": "string"}}}),
        ),
        (
            "/table",
            "ur5.GainTable",
            json!({"type": "object", "properties": {
                "version": int, "checksum": {"type": "string"}, "horizon": int,
                "file": {"type": "string"}}}),
        ),
    ]
}

/// The gain-table files of `run`: `tables/vNNNN.npz`, else `iter_NNN_table.npz`, by version.
fn table_files(run: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let list = |dir: &Path, keep: &dyn Fn(&str) -> bool| -> anyhow::Result<Vec<PathBuf>> {
        let mut f = Vec::new();
        if let Ok(entries) = std::fs::read_dir(dir) {
            for e in entries {
                let p = e
                    .with_context(|| format!("reading {}", dir.display()))?
                    .path();
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

/// Writes the run in `run` (its `episodes/` and tables) to the MCAP file `out` (module docs).
pub fn write_run_mcap(run: &Path, out: &Path) -> anyhow::Result<McapCounts> {
    let episodes = recorded_episodes(&run.join("episodes"))?;
    anyhow::ensure!(
        !episodes.is_empty(),
        "{} holds no recorded episodes (episodes/*.npz; `learner serve` records them, \
         `learner train` with --record-episodes)",
        run.display()
    );
    let mut tables = Vec::new();
    for f in table_files(run)? {
        let t = load_stored(&f).with_context(|| format!("reading {}", f.display()))?;
        tables.push((t.version, t.checksum, t.arrays[0].1[0], f));
    }

    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        super::create_dir(dir)?;
    }
    let file = std::fs::File::create(out).with_context(|| format!("creating {}", out.display()))?;
    let mut w = mcap::WriteOptions::new()
        .compression(None)
        .profile("")
        .library(concat!("learner ", env!("CARGO_PKG_VERSION")))
        .create(BufWriter::new(file))?;
    let mut ids = BTreeMap::new();
    for (topic, name, schema) in channels() {
        let s = w.add_schema(name, "jsonschema", &serde_json::to_vec(&schema)?)?;
        let c = w.add_channel(s, topic, "json", &BTreeMap::new())?;
        ids.insert(topic, c);
    }
    let mut counts = McapCounts::default();
    let mut seq = 0u32;
    let mut put =
        |w: &mut mcap::Writer<_>, topic: &'static str, ns: u64, msg: serde_json::Value| {
            seq += 1;
            *counts.messages.entry(topic.to_owned()).or_default() += 1;
            let header = mcap::records::MessageHeader {
                channel_id: ids[topic],
                sequence: seq,
                log_time: ns,
                publish_time: ns,
            };
            w.write_to_known_channel(&header, &serde_json::to_vec(&msg)?)
                .map_err(anyhow::Error::from)
        };
    let table_msg = |(version, checksum, horizon, file): &(u64, u64, u64, PathBuf)| {
        json!({"version": version, "checksum": format!("{checksum:#018x}"),
               "horizon": horizon, "file": file.display().to_string()})
    };

    let mut start = 0.0f64;
    let mut tables_left: Vec<_> = tables.iter().collect();
    for (path, ep, origin) in &episodes {
        let task =
            load_episode_task(path).with_context(|| format!("reading {}", path.display()))?;
        let ns = |t: usize| ((start + t as f64 * task.dt) * 1e9).round() as u64;
        let v = origin.table_version;
        // Tables up to this version come into force now.
        while let Some(t) = tables_left.first().filter(|t| t.0 <= v) {
            put(&mut w, "/table", ns(0), table_msg(t))?;
            tables_left.remove(0);
        }
        let (e, noisy) = (origin.episode, ep.noisy);
        for t in 0..ep.horizon() {
            let s = ep.state(t);
            let (sec, nsec) = (ns(t) / 1_000_000_000, ns(t) % 1_000_000_000);
            put(
                &mut w,
                "/joint_states",
                ns(t),
                json!({
                "header": {"stamp": {"sec": sec, "nsec": nsec}, "frame_id": "base"},
                "name": ACTIVE_JOINTS, "position": &s[0..3], "velocity": &s[3..6],
                "effort": [] }),
            )?;
            put(
                &mut w,
                "/state",
                ns(t),
                json!({
                "episode": e, "table_version": v, "noisy": noisy, "t": t,
                "q": &s[0..3], "qd": &s[3..6], "ee_minus_goal": &s[6..9], "ee_vel": &s[9..DX]}),
            )?;
            let executed = &ep.u[t * DU..(t + 1) * DU];
            let policy = &ep.u_policy[t * DU..(t + 1) * DU];
            put(
                &mut w,
                "/action",
                ns(t),
                json!({
                "episode": e, "table_version": v, "t": t, "executed": executed, "policy": policy}),
            )?;
            if executed != policy {
                put(
                    &mut w,
                    "/fault",
                    ns(t),
                    json!({
                    "episode": e, "table_version": v, "t": t, "kind": "action_clamped",
                    "executed": executed, "policy": policy}),
                )?;
            }
        }
        let last = ep.horizon() - 1;
        put(
            &mut w,
            "/episode",
            ns(last),
            json!({
            "episode": e, "table_version": v, "noisy": noisy, "task_cost": ep.task_cost(),
            "final_distance_m": ep.final_distance(), "file": path.display().to_string()}),
        )?;
        start += ep.horizon() as f64 * task.dt;
        counts.episodes += 1;
    }
    let end = (start * 1e9).round() as u64;
    for t in tables_left {
        put(&mut w, "/table", end, table_msg(t))?;
    }
    counts.tables = tables.len();
    w.finish()?;
    Ok(counts)
}
