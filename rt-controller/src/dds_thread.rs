//! What the loop's DDS users share (the `ros2` arm, [`crate::arm::ros2`], and the live view,
//! [`crate::live_view`]): DDS (RustDDS) runs on a thread of its own, which may allocate and
//! block; the loop hands it fixed-size values through preallocated lock-free queues
//! ([`Handoff`]) and, where latency matters, wakes it with one `eventfd` write
//! ([`Wake::notify`]). Nothing the loop calls here allocates or locks.

use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use crossbeam_queue::ArrayQueue;
use rustdds::mio1::Registry;

/// A preallocated lock-free queue of fixed-size values (crossbeam `ArrayQueue`) between the
/// loop and a DDS thread; when it is full, the oldest value is dropped (counted), so neither
/// side ever blocks on the other.
pub(crate) struct Handoff<T> {
    queue: ArrayQueue<T>,
    dropped: AtomicU64,
}

impl<T> Handoff<T> {
    /// Room for `capacity` values (allocated here, once).
    pub(crate) fn new(capacity: usize) -> Self {
        Self {
            queue: ArrayQueue::new(capacity),
            dropped: AtomicU64::new(0),
        }
    }

    /// Queues `v`; when full, drops the oldest queued value. No allocation, no lock.
    #[inline]
    pub(crate) fn push(&self, v: T) {
        if self.queue.force_push(v).is_some() {
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// The oldest queued value.
    #[inline]
    pub(crate) fn pop(&self) -> Option<T> {
        self.queue.pop()
    }

    /// Nothing queued.
    #[inline]
    pub(crate) fn is_empty(&self) -> bool {
        self.queue.is_empty()
    }

    /// Values dropped because the queue was full.
    pub(crate) fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }
}

/// A DDS thread's wake-up (`eventfd`) and stop flag.
pub(crate) struct Wake {
    fd: OwnedFd,
    stop: AtomicBool,
}

impl Wake {
    pub(crate) fn new() -> std::io::Result<Self> {
        // SAFETY: eventfd returns a new descriptor or -1.
        let fd = unsafe { libc::eventfd(0, libc::EFD_NONBLOCK | libc::EFD_CLOEXEC) };
        if fd < 0 {
            return Err(std::io::Error::last_os_error());
        }
        Ok(Self {
            // SAFETY: fd is a fresh descriptor we own.
            fd: unsafe { OwnedFd::from_raw_fd(fd) },
            stop: AtomicBool::new(false),
        })
    }

    /// Wakes the thread now (one `write` on the eventfd; no allocation).
    #[inline]
    pub(crate) fn notify(&self) {
        let one = 1u64.to_ne_bytes();
        // SAFETY: writes 8 bytes from a live buffer to our eventfd.
        let _ = unsafe { libc::write(self.fd.as_raw_fd(), one.as_ptr().cast(), 8) };
    }

    fn drain(&self) {
        let mut buf = [0u8; 8];
        // SAFETY: reads at most 8 bytes into a live buffer from our non-blocking eventfd.
        let _ = unsafe { libc::read(self.fd.as_raw_fd(), buf.as_mut_ptr().cast(), 8) };
    }
}

/// What a DDS thread does: registers its readers, then one step after every wake-up.
pub(crate) trait DdsWork: Send + 'static {
    /// Registers the readers whose data should wake the thread (tokens below `usize::MAX`).
    fn register(&mut self, _registry: &Registry) {}
    /// Moves data both ways; called after every wake-up, reader event or timeout.
    fn step(&mut self);
}

/// A running DDS thread: waits in epoll (mio 1) on its readers and its [`Wake`], at most
/// `timeout`, then runs [`DdsWork::step`]; stopped and joined on drop.
pub(crate) struct DdsThread {
    wake: Arc<Wake>,
    handle: Option<JoinHandle<()>>,
}

impl DdsThread {
    /// Starts the thread `name` running `work`.
    pub(crate) fn spawn(
        name: &str,
        wake: Arc<Wake>,
        timeout: Duration,
        mut work: impl DdsWork,
    ) -> std::io::Result<Self> {
        let w = Arc::clone(&wake);
        let handle = std::thread::Builder::new()
            .name(name.into())
            .spawn(move || {
                use rustdds::mio1::unix::SourceFd;
                use rustdds::mio1::{Events, Interest, Poll, Token};
                let mut poll = Poll::new().expect("mio poll");
                work.register(poll.registry());
                let fd = w.fd.as_raw_fd();
                let _ = poll.registry().register(
                    &mut SourceFd(&fd),
                    Token(usize::MAX),
                    Interest::READABLE,
                );
                let mut events = Events::with_capacity(16);
                while !w.stop.load(Ordering::Relaxed) {
                    let _ = poll.poll(&mut events, Some(timeout));
                    w.drain();
                    work.step();
                }
            })?;
        Ok(Self {
            wake,
            handle: Some(handle),
        })
    }

    /// The thread ended (it only does when stopped, or when it panicked).
    #[inline]
    pub(crate) fn is_finished(&self) -> bool {
        self.handle.as_ref().is_none_or(|h| h.is_finished())
    }
}

impl Drop for DdsThread {
    fn drop(&mut self) {
        self.wake.stop.store(true, Ordering::Relaxed);
        self.wake.notify();
        if let Some(t) = self.handle.take() {
            let _ = t.join();
        }
    }
}
