//! Incremental RTDE frame decoding over a fixed buffer.
//!
//! TCP delivers bytes, not packages: one read may end inside a package or hold several. The
//! decoder keeps the bytes of incomplete frames in an array of `N` bytes it owns (no allocation
//! after construction) and yields complete frames as they become available.
//!
//! ```
//! # use ur_protocol::stream::FrameDecoder;
//! let mut dec = FrameDecoder::<256>::new();
//! dec.push(&[0x00, 0x04]);                       // half a START answer
//! assert!(dec.next_frame().unwrap().is_none());
//! dec.push(&[0x53, 0x01, 0x00, 0x03, 0x50]);     // its end, then a PAUSE request
//! assert_eq!(dec.next_frame().unwrap().unwrap().payload, &[1]);
//! assert_eq!(dec.next_frame().unwrap().unwrap().payload, &[] as &[u8]);
//! ```

use crate::rtde::HEADER_LEN;

/// Whether a read or write on a TCP socket ended because its timeout (`set_read_timeout`,
/// `set_write_timeout`) expired: Unix reports `WouldBlock`, Windows `TimedOut`.
pub fn timed_out(e: &std::io::Error) -> bool {
    matches!(
        e.kind(),
        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
    )
}
pub use crate::rtde::{Frame, FrameError};

/// Frames from a byte stream. `N` is the buffer size: the largest frame accepted.
#[derive(Clone, Debug)]
pub struct FrameDecoder<const N: usize> {
    buf: [u8; N],
    /// Start of the bytes not yet returned as frames.
    start: usize,
    /// End of the buffered bytes.
    end: usize,
}

impl<const N: usize> Default for FrameDecoder<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> FrameDecoder<N> {
    /// An empty decoder.
    pub const fn new() -> Self {
        Self {
            buf: [0; N],
            start: 0,
            end: 0,
        }
    }

    /// Forgets every buffered byte (after a reconnect).
    pub fn clear(&mut self) {
        self.start = 0;
        self.end = 0;
    }

    /// Bytes buffered and not yet returned as frames.
    pub fn buffered(&self) -> usize {
        self.end - self.start
    }

    /// Moves the unreturned bytes to the front, so that the free tail is as long as possible.
    fn compact(&mut self) {
        if self.start > 0 {
            self.buf.copy_within(self.start..self.end, 0);
            self.end -= self.start;
            self.start = 0;
        }
    }

    /// The free part of the buffer, to read into directly (e.g. `socket.read(dec.spare())`);
    /// then call [`Self::commit`] with the count read. Empty only if a whole buffer of bytes
    /// is pending, which [`Self::next_frame`] reports as an error first.
    pub fn spare(&mut self) -> &mut [u8] {
        self.compact();
        &mut self.buf[self.end..]
    }

    /// Marks `n` bytes of [`Self::spare`] as received (clamped to its length).
    pub fn commit(&mut self, n: usize) {
        self.end = (self.end + n).min(N);
    }

    /// Copies as many bytes of `data` as fit; returns how many. Call [`Self::next_frame`] until
    /// it yields `None`, then push the rest.
    pub fn push(&mut self, data: &[u8]) -> usize {
        let spare = self.spare();
        let n = data.len().min(spare.len());
        spare[..n].copy_from_slice(&data[..n]);
        self.commit(n);
        n
    }

    /// The next complete frame, `Ok(None)` if more bytes are needed. After an error the
    /// stream's framing is lost: the same error is returned until [`Self::clear`].
    pub fn next_frame(&mut self) -> Result<Option<Frame<'_>>, FrameError> {
        let (kind, len) = match Frame::parse(&self.buf[self.start..self.end], N)? {
            None => return Ok(None),
            Some((f, len)) => (f.kind, len),
        };
        let at = self.start;
        self.start += len;
        if self.start == self.end {
            self.start = 0;
            self.end = 0;
        }
        // The frame's bytes stay in place until the next push or read.
        Ok(Some(Frame {
            kind,
            payload: &self.buf[at + HEADER_LEN..at + len],
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rtde::PackageType;

    #[test]
    fn split_and_merged_packages() {
        let mut dec = FrameDecoder::<64>::new();
        // Two START answers in one read, then one split over two.
        let stream = [0, 4, b'S', 1, 0, 4, b'S', 0, 0, 4, b'P', 1];
        assert_eq!(dec.push(&stream[..9]), 9);
        let f = dec.next_frame().unwrap().unwrap();
        assert_eq!((f.kind, f.payload), (PackageType::Start, &[1u8][..]));
        let f = dec.next_frame().unwrap().unwrap();
        assert_eq!(f.payload, &[0]);
        assert!(dec.next_frame().unwrap().is_none());
        dec.push(&stream[9..]);
        let f = dec.next_frame().unwrap().unwrap();
        assert_eq!((f.kind, f.payload), (PackageType::Pause, &[1u8][..]));
        assert_eq!(dec.buffered(), 0);
    }

    #[test]
    fn oversize_frame_is_an_error_not_a_hang() {
        let mut dec = FrameDecoder::<8>::new();
        dec.push(&[0, 9, b'U', 1, 2, 3, 4, 5]);
        assert_eq!(
            dec.next_frame(),
            Err(FrameError::TooLarge {
                size: 9,
                capacity: 8
            })
        );
        assert_eq!(dec.push(&[6]), 0);
    }
}
