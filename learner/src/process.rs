//! Spawned processes of this build: finding a binary next to the running one, and a child that
//! is stopped (and reaped) when its handle drops. Used by the IPC experiment
//! (`experiment::ipc`) and the cross-process tests (`tests/`).

use std::ffi::OsStr;
use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// What went wrong with a spawned process.
#[derive(Debug, thiserror::Error)]
pub enum ProcessError {
    /// The binary is not next to the running executable.
    #[error(
        "{name} not found next to {exe}: build every binary first (`cargo build --release \
         --workspace --bins`)"
    )]
    NotFound { name: String, exe: PathBuf },
    /// Spawning, waiting or the log file failed.
    #[error("{what}: {source}")]
    Io {
        what: String,
        source: std::io::Error,
    },
    /// Still running after the time it was given.
    #[error("{name} did not exit within {timeout:?}")]
    Timeout { name: String, timeout: Duration },
}

/// The binary `name` of this build: next to the running executable (`target/release/learner`)
/// or one folder up (a test executable in `target/release/deps/`).
pub fn sibling(name: &str) -> Result<PathBuf, ProcessError> {
    let exe = std::env::current_exe().map_err(|source| ProcessError::Io {
        what: "locating the running executable".into(),
        source,
    })?;
    let dir = exe.parent().unwrap_or(Path::new("."));
    [Some(dir.join(name)), dir.parent().map(|d| d.join(name))]
        .into_iter()
        .flatten()
        .find(|p| p.is_file())
        .ok_or_else(|| ProcessError::NotFound {
            name: name.into(),
            exe: exe.clone(),
        })
}

/// A spawned binary: stdin closed, stdout piped (its `--json` line), stderr into a log file,
/// iceoryx2 logging at errors only. On drop it gets SIGTERM (the project's binaries then stop
/// cleanly and remove their iceoryx2 ports), `grace` to exit, and is killed after that.
pub struct Spawned {
    /// What it is, for messages.
    pub name: String,
    child: Option<Child>,
    log: PathBuf,
    grace: Duration,
}

impl Spawned {
    /// Starts `bin` with `args`, its stderr into `log`; `grace` as in the type's docs.
    pub fn spawn<S: AsRef<OsStr>>(
        bin: &Path,
        args: &[S],
        log: &Path,
        grace: Duration,
    ) -> Result<Self, ProcessError> {
        let io = |what: String| move |source| ProcessError::Io { what, source };
        let stderr = File::create(log).map_err(io(format!("creating {}", log.display())))?;
        let child = Command::new(bin)
            .args(args)
            .env("IOX2_LOG_LEVEL", "Error")
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(stderr)
            .spawn()
            .map_err(io(format!("starting {}", bin.display())))?;
        Ok(Self {
            name: bin
                .file_name()
                .map_or_else(|| bin.display().to_string(), |n| n.to_string_lossy().into()),
            child: Some(child),
            log: log.to_owned(),
            grace,
        })
    }

    /// Renames it for messages.
    pub fn named(mut self, name: &str) -> Self {
        self.name = name.into();
        self
    }

    /// The process id (0 once it has been waited for).
    pub fn pid(&self) -> i32 {
        self.child.as_ref().map_or(0, |c| c.id() as i32)
    }

    /// Sends signal `sig` (e.g. `libc::SIGTERM`, `libc::SIGKILL`); nothing once it has exited.
    pub fn signal(&self, sig: i32) {
        if let Some(c) = self.child.as_ref() {
            // SAFETY: plain kill(2) on our own child's pid.
            unsafe { libc::kill(c.id() as i32, sig) };
        }
    }

    /// Its stderr so far.
    pub fn log(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// The log file.
    pub fn log_path(&self) -> &Path {
        &self.log
    }

    /// Its exit status if it has exited (then its stdout is kept for [`Spawned::wait`]).
    pub fn try_wait(&mut self) -> Result<Option<ExitStatus>, ProcessError> {
        match self.child.as_mut() {
            Some(c) => c.try_wait().map_err(|source| ProcessError::Io {
                what: format!("waiting for {}", self.name),
                source,
            }),
            None => Ok(None),
        }
    }

    /// True while running.
    pub fn running(&mut self) -> bool {
        matches!(self.try_wait(), Ok(None)) && self.child.is_some()
    }

    /// Waits up to `timeout` for exit; returns (exit code, stdout). On timeout it is killed.
    pub fn wait(&mut self, timeout: Duration) -> Result<(Option<i32>, String), ProcessError> {
        let t0 = Instant::now();
        loop {
            if let Some(status) = self.try_wait()? {
                let mut out = String::new();
                if let Some(mut s) = self.child.as_mut().and_then(|c| c.stdout.take()) {
                    let _ = s.read_to_string(&mut out);
                }
                self.child = None;
                return Ok((status.code(), out));
            }
            if t0.elapsed() > timeout {
                if let Some(c) = self.child.as_mut() {
                    let _ = c.kill();
                }
                return Err(ProcessError::Timeout {
                    name: self.name.clone(),
                    timeout,
                });
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}

impl Drop for Spawned {
    fn drop(&mut self) {
        let Some(c) = self.child.as_mut() else {
            return;
        };
        if !self.grace.is_zero() {
            // SAFETY: plain kill(2) on our own child's pid.
            unsafe { libc::kill(c.id() as i32, libc::SIGTERM) };
            let t0 = Instant::now();
            while t0.elapsed() < self.grace {
                if let Ok(Some(_)) = c.try_wait() {
                    return;
                }
                std::thread::sleep(Duration::from_millis(20));
            }
            eprintln!(
                "{} did not stop on SIGTERM within {:?}; killed",
                self.name, self.grace
            );
        }
        let _ = c.kill();
        let _ = c.wait();
    }
}
