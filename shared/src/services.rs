//! iceoryx2 service names (DESIGN.md §3) and per-run prefixes.
//!
//! Every process builds its names through [`ServiceNames`], so a test (or a second experiment
//! on the same machine) that picks its own prefix never meets another's services
//! (DESIGN.md §5). Payload types per service are listed in [`crate::msg`].

use core::sync::atomic::{AtomicU64, Ordering};

use iceoryx2::prelude::ServiceName;

/// Arm → controller: [`crate::msg::ArmState`].
pub const ARM_STATE: &str = "arm/state";
/// Controller → arm: [`crate::msg::ArmCommand`].
pub const ARM_COMMAND: &str = "arm/command";
/// Controller → learner: [`crate::msg::StepSample`].
pub const LEARNER_SAMPLES: &str = "learner/samples";
/// Learner → controller: [`crate::gains::GainTable`]; history 1, safe overflow (DESIGN.md §3).
pub const CONTROLLER_GAINS: &str = "controller/gains";

/// All base names, in data-flow order.
pub const ALL: [&str; 4] = [ARM_STATE, ARM_COMMAND, LEARNER_SAMPLES, CONTROLLER_GAINS];

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

/// The four service names under one prefix. Built at setup (allocates), never in a loop.
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
