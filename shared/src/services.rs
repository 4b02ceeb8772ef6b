//! iceoryx2 service names (docs/design.md §3.2) and per-run prefixes.
//!
//! Every process builds its names through [`ServiceNames`], so a test (or a second experiment
//! on the same machine) that picks its own prefix never meets another's services
//! (docs/design.md §3.2). Payload types per service are listed in [`crate::msg`].

use core::sync::atomic::{AtomicU64, Ordering};

use iceoryx2::prelude::{ipc, Node, ServiceName, ZeroCopySend};

/// Arm → controller: [`crate::msg::ArmState`].
pub const ARM_STATE: &str = "arm/state";
/// Controller → arm: [`crate::msg::ArmCommand`].
pub const ARM_COMMAND: &str = "arm/command";
/// Controller → learner: [`crate::msg::StepSample`].
pub const LEARNER_SAMPLES: &str = "learner/samples";
/// Learner → controller: [`crate::gains::GainTable`]; history 1, safe overflow (docs/design.md §3.2).
pub const CONTROLLER_GAINS: &str = "controller/gains";
/// Learner → controller: [`crate::policy::PolicyTable`], the second controller kind; same
/// quality of service as `controller/gains` (docs/design.md §3.11).
pub const CONTROLLER_POLICY: &str = "controller/policy";

/// Controller → learner: [`crate::status::PeerStatus`], why the controller stopped.
pub const CONTROLLER_STATUS: &str = "controller/status";
/// Learner → controller: [`crate::status::PeerStatus`], why the learner stopped.
pub const LEARNER_STATUS: &str = "learner/status";

/// All base names, in data-flow order.
pub const ALL: [&str; 7] = [
    ARM_STATE,
    ARM_COMMAND,
    LEARNER_SAMPLES,
    CONTROLLER_GAINS,
    CONTROLLER_POLICY,
    CONTROLLER_STATUS,
    LEARNER_STATUS,
];

/// A service name that iceoryx2 refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("invalid iceoryx2 service name {name:?} ({reason:?}); names must be non-empty, at most {max} bytes and not start with \"iox2://\": shorten the prefix", max = ServiceName::max_len())]
pub struct InvalidServiceName {
    /// The full (prefixed) name.
    pub name: String,
    /// What iceoryx2 said.
    pub reason: iceoryx2::service::service_name::ServiceNameError,
}

/// `base` under `prefix`: `"{prefix}/{base}"`, or `base` alone if the prefix is empty.
/// Slashes at the ends of the prefix are ignored.
pub fn prefixed(prefix: &str, base: &str) -> String {
    let p = prefix.trim_matches('/');
    if p.is_empty() {
        base.to_owned()
    } else {
        format!("{p}/{base}")
    }
}

/// The service names under one prefix. Built at setup (allocates), never in a loop.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ServiceNames {
    /// The prefix ("" for the default, unprefixed names).
    pub prefix: String,
    /// `arm/state` under the prefix.
    pub arm_state: String,
    /// `arm/command` under the prefix.
    pub arm_command: String,
    /// `learner/samples` under the prefix.
    pub learner_samples: String,
    /// `controller/gains` under the prefix.
    pub controller_gains: String,
    /// `controller/policy` under the prefix.
    pub controller_policy: String,
    /// `controller/status` under the prefix.
    pub controller_status: String,
    /// `learner/status` under the prefix.
    pub learner_status: String,
}

impl Default for ServiceNames {
    fn default() -> Self {
        Self::new("")
    }
}

impl ServiceNames {
    /// Names under `prefix` (e.g. `"ur5"`, or a [`unique_prefix`] in tests).
    pub fn new(prefix: &str) -> Self {
        Self {
            prefix: prefix.trim_matches('/').to_owned(),
            arm_state: prefixed(prefix, ARM_STATE),
            arm_command: prefixed(prefix, ARM_COMMAND),
            learner_samples: prefixed(prefix, LEARNER_SAMPLES),
            controller_gains: prefixed(prefix, CONTROLLER_GAINS),
            controller_policy: prefixed(prefix, CONTROLLER_POLICY),
            controller_status: prefixed(prefix, CONTROLLER_STATUS),
            learner_status: prefixed(prefix, LEARNER_STATUS),
        }
    }

    /// Converts one of the names to an iceoryx2 [`ServiceName`].
    pub fn service_name(name: &str) -> Result<ServiceName, InvalidServiceName> {
        ServiceName::new(name).map_err(|reason| InvalidServiceName {
            name: name.to_owned(),
            reason,
        })
    }

    /// `arm/state` as an iceoryx2 name.
    pub fn arm_state(&self) -> Result<ServiceName, InvalidServiceName> {
        Self::service_name(&self.arm_state)
    }
    /// `arm/command` as an iceoryx2 name.
    pub fn arm_command(&self) -> Result<ServiceName, InvalidServiceName> {
        Self::service_name(&self.arm_command)
    }
    /// `learner/samples` as an iceoryx2 name.
    pub fn learner_samples(&self) -> Result<ServiceName, InvalidServiceName> {
        Self::service_name(&self.learner_samples)
    }
    /// `controller/gains` as an iceoryx2 name.
    pub fn controller_gains(&self) -> Result<ServiceName, InvalidServiceName> {
        Self::service_name(&self.controller_gains)
    }
    /// `controller/policy` as an iceoryx2 name.
    pub fn controller_policy(&self) -> Result<ServiceName, InvalidServiceName> {
        Self::service_name(&self.controller_policy)
    }
}

/// Quality of service of one publish–subscribe service (docs/design.md §3.2).
///
/// iceoryx2 fixes these settings when the first process creates a service, and refuses to open
/// it for a process that asks for more (e.g. a larger subscriber buffer). Every process opens
/// the services through [`Qos::open_or_create`] with the constants below, so whichever starts
/// first creates the same service the others expect.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Qos {
    /// Samples a late subscriber receives on connecting (the newest ones).
    pub history: usize,
    /// Largest subscriber queue (samples).
    pub subscriber_buffer: usize,
    /// Largest number of publishers; more than one so that a restarted process can connect
    /// while its dead predecessor is still registered.
    pub max_publishers: usize,
    /// Largest number of subscribers (tests and monitors add their own).
    pub max_subscribers: usize,
    /// A full subscriber queue drops its oldest sample instead of blocking the publisher; the
    /// controller must never wait for a slow or dead peer.
    pub safe_overflow: bool,
}

/// `arm/state`: the newest state only (a controller acts on the latest measurement); history 1
/// so a controller that starts after the arm sees it at once.
pub const ARM_STATE_QOS: Qos = Qos {
    history: 1,
    subscriber_buffer: 1,
    max_publishers: 2,
    max_subscribers: 4,
    safe_overflow: true,
};

/// `arm/command`: no history (an old command must never reach a newly started arm); a short
/// queue the arm drains in order so a reset followed by a goal is not lost.
pub const ARM_COMMAND_QOS: Qos = Qos {
    history: 0,
    subscriber_buffer: 4,
    max_publishers: 2,
    max_subscribers: 4,
    safe_overflow: true,
};

/// `learner/samples`: a queue of 8 full episodes so a learner that is busy with an update
/// loses nothing; when even that overflows, the oldest samples go (the learner counts the
/// incomplete episode and discards it) and the controller never waits.
pub const LEARNER_SAMPLES_QOS: Qos = Qos {
    history: 0,
    subscriber_buffer: 8 * crate::layout::MAX_HORIZON,
    max_publishers: 2,
    max_subscribers: 4,
    safe_overflow: true,
};

/// `controller/gains`: history 1, queue 1, safe overflow (docs/design.md §3.2): only the newest table
/// matters, and a controller that starts late still gets it.
pub const CONTROLLER_GAINS_QOS: Qos = Qos {
    history: 1,
    subscriber_buffer: 1,
    max_publishers: 4,
    max_subscribers: 4,
    safe_overflow: true,
};

/// `controller/status`, `learner/status`: no history (a status is about the peer that is
/// connected now, never a dead predecessor), a queue of 2.
pub const STATUS_QOS: Qos = Qos {
    history: 0,
    subscriber_buffer: 2,
    max_publishers: 2,
    max_subscribers: 4,
    safe_overflow: true,
};

/// `controller/policy`: as `controller/gains` (the newest table of either kind is the
/// controller; docs/design.md §3.11).
pub const CONTROLLER_POLICY_QOS: Qos = CONTROLLER_GAINS_QOS;

impl Qos {
    /// Opens the service `name` with payload `T`, or creates it with these settings. Setup
    /// only: allocates, and may fail (e.g. a service of that name exists with another payload
    /// type or smaller limits).
    pub fn open_or_create<T: core::fmt::Debug + ZeroCopySend + 'static>(
        &self,
        node: &Node<ipc::Service>,
        name: &ServiceName,
    ) -> Result<
        iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, T, ()>,
        iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenOrCreateError,
    > {
        node.service_builder(name)
            .publish_subscribe::<T>()
            .history_size(self.history)
            .subscriber_max_buffer_size(self.subscriber_buffer)
            .max_publishers(self.max_publishers)
            .max_subscribers(self.max_subscribers)
            .enable_safe_overflow(self.safe_overflow)
            .open_or_create()
    }
}

/// A service that could not be opened or created after [`Qos::open_or_create_retrying`]'s
/// attempts.
#[derive(Debug, thiserror::Error)]
pub enum OpenServiceError {
    /// The name is not a valid iceoryx2 service name.
    #[error(transparent)]
    Name(#[from] InvalidServiceName),
    /// Every attempt failed; `why` is iceoryx2's last error.
    #[error("cannot open or create service `{name}` after {attempts} attempts: {why:?}; a service of that name may exist with another payload type or smaller limits (another build of the project, or a stale run: use a fresh --prefix)")]
    Service {
        /// Full (prefixed) service name.
        name: String,
        /// Attempts made.
        attempts: u32,
        /// iceoryx2's last error.
        why: iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenOrCreateError,
    },
}

impl Qos {
    /// Attempts made by [`Qos::open_or_create_retrying`]; the waits between them grow from
    /// 2 ms by 1 ms each, about 1.3 s in all.
    pub const OPEN_ATTEMPTS: u32 = 50;

    /// [`Qos::open_or_create`] for the full name `name`, retried while another process may be
    /// creating the same service at this moment (iceoryx2 reports a service in creation as an
    /// error to the opener). Setup only: allocates and sleeps.
    pub fn open_or_create_retrying<T: core::fmt::Debug + ZeroCopySend + 'static>(
        &self,
        node: &Node<ipc::Service>,
        name: &str,
    ) -> Result<
        iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, T, ()>,
        OpenServiceError,
    > {
        let sname = ServiceNames::service_name(name)?;
        let mut attempt = 0;
        loop {
            match self.open_or_create::<T>(node, &sname) {
                Ok(f) => return Ok(f),
                Err(why) if attempt + 1 >= Self::OPEN_ATTEMPTS => {
                    return Err(OpenServiceError::Service {
                        name: name.to_owned(),
                        attempts: Self::OPEN_ATTEMPTS,
                        why,
                    })
                }
                Err(_) => {
                    std::thread::sleep(std::time::Duration::from_millis(2 + u64::from(attempt)))
                }
            }
            attempt += 1;
        }
    }
}

/// A prefix no other live process or earlier run will use: `"test/{tag}/{pid}-{ns}-{n}"`
/// (process id, wall-clock ns, per-process counter). For tests that run in parallel and for
/// leftovers of a crashed test that must not disturb the next.
pub fn unique_prefix(tag: &str) -> String {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let ns = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos())
        .unwrap_or(0);
    format!("test/{tag}/{}-{ns}-{n}", std::process::id())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prefixing() {
        assert_eq!(prefixed("", ARM_STATE), "arm/state");
        assert_eq!(prefixed("/", ARM_STATE), "arm/state");
        assert_eq!(prefixed("run7/", ARM_COMMAND), "run7/arm/command");
        let n = ServiceNames::new("exp");
        assert_eq!(n.learner_samples, "exp/learner/samples");
        assert_eq!(
            n.controller_gains().unwrap().as_str(),
            "exp/controller/gains"
        );
        assert_eq!(ServiceNames::default().arm_state, "arm/state");
    }

    #[test]
    fn unique_prefixes_differ_and_are_valid_names() {
        let a = unique_prefix("x");
        let b = unique_prefix("x");
        assert_ne!(a, b);
        let names = ServiceNames::new(&a);
        names.arm_state().unwrap();
        names.controller_gains().unwrap();
    }

    #[test]
    fn invalid_names_are_reported() {
        let long = "p".repeat(ServiceName::max_len() + 1);
        let err = ServiceNames::new(&long).arm_state().unwrap_err();
        assert!(err.to_string().contains("shorten the prefix"));
        assert!(ServiceNames::service_name("iox2://x").is_err());
    }
}

/// One process per role on a prefix (docs/design.md §3.2): the controller,
/// the arm and the learner each hold an exclusive `flock` on
/// `{temp_dir}/ur5-gaifo-locks/{prefix}.{role}.lock` for their lifetime. The kernel drops the
/// lock when the process ends, however it ends (kill -9 included), so a restart always gets
/// it; a second process of the same role while the first runs does not, and says who holds it.
/// Setup only (opens a file).
#[derive(Debug)]
pub struct RoleLock {
    _file: std::fs::File,
    /// The lock file.
    pub path: std::path::PathBuf,
}

/// Why a [`RoleLock`] could not be taken.
#[derive(Debug, thiserror::Error)]
pub enum RoleLockError {
    /// Another live process holds the role.
    #[error("another {role} is running on prefix `{prefix}` (pid {pid}; lock {path}): stop it first, or give this one another --prefix")]
    Taken {
        /// `controller`, `arm` or `learner`.
        role: &'static str,
        /// The prefix.
        prefix: String,
        /// Its process id, as it wrote it ("?" if unreadable).
        pid: String,
        /// The lock file.
        path: std::path::PathBuf,
    },
    /// The lock file could not be opened.
    #[error("cannot open the lock file {path}: {source}")]
    Io {
        /// The lock file.
        path: std::path::PathBuf,
        /// The error.
        source: std::io::Error,
    },
}

impl RoleLock {
    /// The lock file of `role` on `prefix` (slashes in the prefix become `%`).
    pub fn path(prefix: &str, role: &str) -> std::path::PathBuf {
        let name: String = prefix
            .trim_matches('/')
            .chars()
            .map(|c| if c == '/' { '%' } else { c })
            .collect();
        std::env::temp_dir()
            .join("ur5-gaifo-locks")
            .join(format!("{name}.{role}.lock"))
    }

    /// Takes `role` on `prefix`, or says which process has it.
    pub fn acquire(prefix: &str, role: &'static str) -> Result<Self, RoleLockError> {
        use std::io::{Read, Seek, Write};
        use std::os::fd::AsRawFd;
        let path = Self::path(prefix, role);
        let dir = path.parent().expect("a lock file has a folder").to_owned();
        let io = |source| RoleLockError::Io {
            path: path.clone(),
            source,
        };
        std::fs::create_dir_all(&dir).map_err(io)?;
        let mut file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(io)?;
        // SAFETY: flock on a file descriptor this function owns.
        let r = unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) };
        if r != 0 {
            let err = std::io::Error::last_os_error();
            if err.raw_os_error() != Some(libc::EWOULDBLOCK) {
                return Err(io(err));
            }
            let mut pid = String::new();
            let _ = file.read_to_string(&mut pid);
            let pid = pid.trim();
            return Err(RoleLockError::Taken {
                role,
                prefix: prefix.to_owned(),
                pid: if pid.is_empty() {
                    "?".into()
                } else {
                    pid.to_owned()
                },
                path,
            });
        }
        file.set_len(0).map_err(io)?;
        file.rewind().map_err(io)?;
        write!(file, "{}", std::process::id()).map_err(io)?;
        Ok(Self { _file: file, path })
    }
}

#[cfg(test)]
mod role_lock_tests {
    use super::*;

    #[test]
    fn a_role_has_one_holder_until_it_is_dropped() {
        let prefix = unique_prefix("role-lock");
        let a = RoleLock::acquire(&prefix, "controller").unwrap();
        let e = RoleLock::acquire(&prefix, "controller")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("another controller is running")
                && e.contains(&std::process::id().to_string()),
            "{e}"
        );
        // Other roles and other prefixes are independent.
        let _arm = RoleLock::acquire(&prefix, "arm").unwrap();
        let _other = RoleLock::acquire(&unique_prefix("role-lock"), "controller").unwrap();
        drop(a);
        RoleLock::acquire(&prefix, "controller").unwrap();
    }
}
