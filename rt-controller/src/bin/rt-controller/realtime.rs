//! `rt-controller bench --real-time`: wake-up lateness of the loop's absolute-deadline sleep
//! ([`rt_controller::latency`]) and, when `cyclictest` (Debian package rt-tests) is on PATH,
//! cyclictest's at the same rate, same number of wake-ups and same privileges, run at the same
//! time, in one table.

use std::path::Path;
use std::process::{Child, Command, Stdio};

use anyhow::{anyhow, Context, Result};
use serde::Serialize;
use serde_json::Value;

use rt_controller::config::RtSetup;
use rt_controller::latency::{measure_wakeups, schedule, LatencyReport};

/// cyclictest's histogram range (µs); later wake-ups count as overflows (their percentile is
/// then cyclictest's maximum).
const CYCLICTEST_HIST_US: u64 = 100_000;

/// cyclictest's figures (µs, its 1 µs histogram bins).
#[derive(Clone, Debug, Serialize)]
pub struct CyclictestFigures {
    /// `rt_test_version` of its JSON.
    pub version: String,
    /// Its command line.
    pub command: String,
    /// Wake-ups (its `cycles`).
    pub wakeups: u64,
    pub p50_us: f64,
    pub p99_us: f64,
    pub p999_us: f64,
    pub max_us: f64,
}

/// Both measurements.
#[derive(Clone, Debug, Serialize)]
pub struct RealTimeReport {
    /// Always "bench --real-time".
    pub command: &'static str,
    pub rate_hz: f64,
    pub seconds: f64,
    pub ours: LatencyReport,
    /// `None` when cyclictest is not installed or failed (`cyclictest_note` says which).
    pub cyclictest: Option<CyclictestFigures>,
    pub cyclictest_note: Option<String>,
}

/// Runs both for `seconds` at `rate_hz` with the privileges of `setup`.
pub fn run(rate_hz: f64, seconds: f64, setup: &RtSetup) -> Result<RealTimeReport> {
    let (period_ns, wakeups) = schedule(rate_hz, seconds)?;
    let dir = std::env::temp_dir().join(format!("rt-bench-cyclictest-{}", std::process::id()));
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut args: Vec<String> = vec![
        "-q".into(),
        "-t".into(),
        "1".into(),
        "-i".into(),
        ((period_ns + 500) / 1000).max(1).to_string(),
        "-l".into(),
        wakeups.to_string(),
        "-h".into(),
        CYCLICTEST_HIST_US.to_string(),
        format!("--histfile={}", dir.join("histogram.txt").display()),
        format!("--json={}", dir.join("result.json").display()),
    ];
    if setup.fifo_priority > 0 {
        args.extend(["-p".into(), setup.fifo_priority.to_string()]);
    }
    if setup.mlockall {
        args.push("-m".into());
    }
    if let Some(cpu) = setup.cpu {
        args.extend(["-a".into(), cpu.to_string()]);
    }
    let command = format!("cyclictest {}", args.join(" "));
    let child = Command::new("cyclictest")
        .args(&args)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn();
    let (child, mut note) = match child {
        Ok(c) => (Some(c), None),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => (
            None,
            Some("cyclictest is not installed (Debian package rt-tests: apt-get install rt-tests); only ours was measured".to_string()),
        ),
        Err(e) => (None, Some(format!("cyclictest did not start: {e}"))),
    };
    let setup_ours = setup.clone();
    let ours = std::thread::Builder::new()
        .name("rt-bench-wakeups".into())
        .spawn(move || measure_wakeups(rate_hz, seconds, &setup_ours))
        .context("starting the measuring thread")?
        .join()
        .map_err(|_| anyhow!("the measuring thread panicked"))??;
    let cyclictest = match child {
        Some(c) => match finish_cyclictest(c, &dir, command) {
            Ok(f) => Some(f),
            Err(e) => {
                note = Some(format!("cyclictest failed: {e:#}"));
                None
            }
        },
        None => None,
    };
    let _ = std::fs::remove_dir_all(&dir);
    Ok(RealTimeReport {
        command: "bench --real-time",
        rate_hz,
        seconds,
        ours,
        cyclictest,
        cyclictest_note: note,
    })
}

/// Waits for cyclictest and reads its JSON result.
fn finish_cyclictest(child: Child, dir: &Path, command: String) -> Result<CyclictestFigures> {
    let out = child.wait_with_output().context("waiting for cyclictest")?;
    if !out.status.success() {
        anyhow::bail!(
            "{} ({})",
            out.status,
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    let path = dir.join("result.json");
    let text =
        std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let v: Value =
        serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
    parse_cyclictest(&v, command)
}

/// cyclictest's JSON (`--json`, rt-tests 2.x): thread 0's `cycles`, `max` and its `histogram`
/// ({"µs": count}) give the percentiles.
fn parse_cyclictest(v: &Value, command: String) -> Result<CyclictestFigures> {
    let t = &v["thread"]["0"];
    let wakeups = t["cycles"]
        .as_u64()
        .ok_or_else(|| anyhow!("no thread.0.cycles in cyclictest's JSON"))?;
    let max_us = t["max"]
        .as_f64()
        .ok_or_else(|| anyhow!("no thread.0.max in cyclictest's JSON"))?;
    let mut bins: Vec<(u64, u64)> = t["histogram"]
        .as_object()
        .ok_or_else(|| anyhow!("no thread.0.histogram in cyclictest's JSON"))?
        .iter()
        .map(|(k, c)| Ok((k.parse::<u64>()?, c.as_u64().unwrap_or(0))))
        .collect::<Result<_, std::num::ParseIntError>>()
        .context("cyclictest histogram keys")?;
    bins.sort_unstable();
    // Rank ⌈q n⌉ over the bins; a rank past the histogram is an overflow (beyond its range).
    let quantile = |q: f64| -> f64 {
        let rank = ((q * wakeups as f64).ceil() as u64).clamp(1, wakeups.max(1));
        let mut seen = 0;
        for &(us, c) in &bins {
            seen += c;
            if seen >= rank {
                return us as f64;
            }
        }
        max_us
    };
    Ok(CyclictestFigures {
        version: v["rt_test_version:"]
            .as_str()
            .or(v["rt_test_version"].as_str())
            .unwrap_or("?")
            .to_string(),
        command,
        wakeups,
        p50_us: quantile(0.5),
        p99_us: quantile(0.99),
        p999_us: quantile(0.999),
        max_us,
    })
}

/// Prints the table (µs).
pub fn print(r: &RealTimeReport, setup: &RtSetup) {
    let policy = if r.ours.rt.sched_fifo == Some(true) {
        format!("SCHED_FIFO {}", setup.fifo_priority)
    } else {
        "normal scheduler (SCHED_OTHER)".to_string()
    };
    println!(
        "rt-controller bench --real-time: {} Hz ({} ns period) for {} s, clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME), {policy}; both loops at the same time",
        r.rate_hz, r.ours.period_ns, r.seconds
    );
    println!("| wake-up lateness (µs) | wake-ups | p50 | p99 | p99.9 | max |");
    println!("|---|---|---|---|---|---|");
    let p = &r.ours.lateness;
    let us = |v: u64| v as f64 / 1e3;
    println!(
        "| rt-controller (histogram bins ≤ 3 %) | {} | {:.1} | {:.1} | {:.1} | {:.1} |",
        p.count,
        us(p.p50_ns),
        us(p.p99_ns),
        us(p.p999_ns),
        us(p.max_ns)
    );
    match (&r.cyclictest, &r.cyclictest_note) {
        (Some(c), _) => println!(
            "| cyclictest {} (1 µs bins) | {} | {:.0} | {:.0} | {:.0} | {:.0} |",
            c.version, c.wakeups, c.p50_us, c.p99_us, c.p999_us, c.max_us
        ),
        (None, Some(n)) => println!("| cyclictest | — | — | — | — | — |\n{n}"),
        (None, None) => {}
    }
    if let Some(c) = &r.cyclictest {
        println!("cyclictest ran as: {}", c.command);
    }
    for n in &r.ours.rt.notes {
        println!("note: {n}");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_cyclictest_json_percentiles() {
        // The shape rt-tests 2.40 writes, 10 wake-ups: 8 µs ×5, 9 ×4, one past the histogram.
        let v: Value = serde_json::from_str(
            r#"{"rt_test_version:": "2.40", "thread": {"0": {"histogram": {"9": 4, "8": 5},
                "cycles": 10, "min": 8, "max": 250000, "avg": 25009.0}}}"#,
        )
        .unwrap();
        let f = parse_cyclictest(&v, "cyclictest -q".into()).unwrap();
        assert_eq!(f.version, "2.40");
        assert_eq!(f.wakeups, 10);
        assert_eq!((f.p50_us, f.p99_us, f.max_us), (8.0, 250000.0, 250000.0));
        let f = parse_cyclictest(
            &serde_json::from_str(
                r#"{"thread": {"0": {"histogram": {"8": 1}, "cycles": 1, "max": 8}}}"#,
            )
            .unwrap(),
            String::new(),
        )
        .unwrap();
        assert_eq!((f.p50_us, f.p99_us, f.version.as_str()), (8.0, 8.0, "?"));
        assert!(parse_cyclictest(&serde_json::json!({}), String::new()).is_err());
    }
}
