//! Why a peer stopped: the fatal-status payload the controller and the learner send each other
//! (docs/design.md §3.12). When one side finds that the two cannot work
//! together (the controller rejects the learner's tables for a task reason, or the learner finds
//! the controller's episodes are not its task), it publishes a [`PeerStatus`] with the reason on
//! its status service and stops; the other side, which polls its status subscriber while it
//! waits, stops too with the same message. Neither waits silently for the other.
//!
//! | service | publisher → subscriber |
//! |---|---|
//! | `controller/status` | controller → learner |
//! | `learner/status` | learner → controller |
//!
//! The message is UTF-8 in a fixed buffer of [`STATUS_MESSAGE_BYTES`] (truncated at a
//! character boundary), written without allocation ([`PeerStatus::fatal`] takes
//! `fmt::Arguments`), so the controller can send it from its loop.

use core::fmt;

use iceoryx2::prelude::ZeroCopySend;

/// Bytes of the message buffer.
pub const STATUS_MESSAGE_BYTES: usize = 480;

/// A status message (module docs).
#[repr(C)]
#[derive(Clone, Copy, ZeroCopySend)]
#[type_name("ur5_shared::PeerStatus.v1")]
pub struct PeerStatus {
    /// Monotonic ns when it was written.
    pub stamp_ns: u64,
    /// Process id of the sender.
    pub pid: u32,
    /// 1: the sender stopped for the reason in `message`; other values are not sent yet
    /// (receivers ignore them).
    pub code: u32,
    /// Bytes of `message` in use.
    pub len: u32,
    /// Write 0.
    pub reserved: u32,
    /// UTF-8 text, `len` bytes.
    pub message: [u8; STATUS_MESSAGE_BYTES],
}

impl fmt::Debug for PeerStatus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("PeerStatus")
            .field("pid", &self.pid)
            .field("code", &self.code)
            .field("message", &self.text())
            .finish()
    }
}

/// [`PeerStatus::code`] of a fatal status.
pub const FATAL: u32 = 1;

/// Writes into a byte buffer, dropping what does not fit (at a character boundary).
struct Cursor<'a> {
    buf: &'a mut [u8],
    len: usize,
}

impl fmt::Write for Cursor<'_> {
    fn write_str(&mut self, s: &str) -> fmt::Result {
        let room = self.buf.len() - self.len;
        let mut n = s.len().min(room);
        while !s.is_char_boundary(n) {
            n -= 1;
        }
        self.buf[self.len..self.len + n].copy_from_slice(&s.as_bytes()[..n]);
        self.len += n;
        Ok(())
    }
}

impl PeerStatus {
    /// A fatal status with the message `args` (truncated to the buffer), sent at `stamp_ns`.
    /// Does not allocate.
    pub fn fatal(stamp_ns: u64, args: fmt::Arguments<'_>) -> Self {
        let mut s = Self {
            stamp_ns,
            pid: std::process::id(),
            code: FATAL,
            len: 0,
            reserved: 0,
            message: [0; STATUS_MESSAGE_BYTES],
        };
        let mut c = Cursor {
            buf: &mut s.message,
            len: 0,
        };
        let _ = fmt::write(&mut c, args);
        s.len = c.len as u32;
        s
    }

    /// Whether the sender stopped.
    pub fn is_fatal(&self) -> bool {
        self.code == FATAL
    }

    /// The message; invalid UTF-8 (a foreign writer) up to the first bad byte.
    pub fn text(&self) -> &str {
        let bytes = &self.message[..(self.len as usize).min(STATUS_MESSAGE_BYTES)];
        match core::str::from_utf8(bytes) {
            Ok(s) => s,
            Err(e) => core::str::from_utf8(&bytes[..e.valid_up_to()]).unwrap_or(""),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_round_trip_and_truncate_at_a_character_boundary() {
        let s = PeerStatus::fatal(5, format_args!("T = {} ≠ {}", 50, 100));
        assert!(s.is_fatal());
        assert_eq!(s.text(), "T = 50 ≠ 100");
        let long = "é".repeat(STATUS_MESSAGE_BYTES); // 2 bytes each
        let s = PeerStatus::fatal(0, format_args!("x{long}"));
        assert_eq!(s.len as usize, STATUS_MESSAGE_BYTES - 1);
        assert!(s.text().starts_with("xé"));
        let mut bad = s;
        bad.message[3] = 0xff;
        assert_eq!(bad.text(), "xé");
        bad.len = u32::MAX;
        assert!(!bad.text().is_empty());
    }
}
