//! Big-endian cursor reads and writes over borrowed slices, with typed errors instead of panics.

use crate::{DecodeError, EncodeError};

/// Reads big-endian fields from a payload.
pub(crate) struct Reader<'a> {
    data: &'a [u8],
    pos: usize,
    what: &'static str,
}

impl<'a> Reader<'a> {
    pub(crate) fn new(data: &'a [u8], what: &'static str) -> Self {
        Self { data, pos: 0, what }
    }

    pub(crate) fn bytes(&mut self, n: usize) -> Result<&'a [u8], DecodeError> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.data.len());
        match end {
            Some(end) => {
                let s = &self.data[self.pos..end];
                self.pos = end;
                Ok(s)
            }
            None => Err(DecodeError::Truncated {
                what: self.what,
                need: n,
                at: self.pos,
                have: self.data.len(),
            }),
        }
    }

    pub(crate) fn array<const N: usize>(&mut self) -> Result<[u8; N], DecodeError> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.bytes(N)?);
        Ok(a)
    }

    pub(crate) fn u8(&mut self) -> Result<u8, DecodeError> {
        Ok(self.array::<1>()?[0])
    }
    pub(crate) fn u16(&mut self) -> Result<u16, DecodeError> {
        Ok(u16::from_be_bytes(self.array()?))
    }
    pub(crate) fn u32(&mut self) -> Result<u32, DecodeError> {
        Ok(u32::from_be_bytes(self.array()?))
    }
    pub(crate) fn i32(&mut self) -> Result<i32, DecodeError> {
        Ok(i32::from_be_bytes(self.array()?))
    }
    pub(crate) fn u64(&mut self) -> Result<u64, DecodeError> {
        Ok(u64::from_be_bytes(self.array()?))
    }
    pub(crate) fn f64(&mut self) -> Result<f64, DecodeError> {
        Ok(f64::from_be_bytes(self.array()?))
    }

    /// A `u8` length followed by that many UTF-8 bytes.
    pub(crate) fn short_str(&mut self) -> Result<&'a str, DecodeError> {
        let n = self.u8()? as usize;
        let what = self.what;
        core::str::from_utf8(self.bytes(n)?).map_err(|_| DecodeError::NotUtf8 { what })
    }

    /// Everything left, as UTF-8.
    pub(crate) fn rest_str(&mut self) -> Result<&'a str, DecodeError> {
        let what = self.what;
        core::str::from_utf8(self.rest()).map_err(|_| DecodeError::NotUtf8 { what })
    }

    pub(crate) fn rest(&mut self) -> &'a [u8] {
        let s = &self.data[self.pos..];
        self.pos = self.data.len();
        s
    }

    /// Fails if bytes are left.
    pub(crate) fn end(&self) -> Result<(), DecodeError> {
        match self.data.len() - self.pos {
            0 => Ok(()),
            extra => Err(DecodeError::TrailingBytes {
                what: self.what,
                extra,
            }),
        }
    }
}

/// Writes big-endian fields into a caller-owned buffer.
pub(crate) struct Writer<'a> {
    buf: &'a mut [u8],
    pos: usize,
}

impl<'a> Writer<'a> {
    /// A writer for one framed package: the payload starts after a header of `header_len`
    /// bytes, which the caller fills in last (RTDE: `rtde::HEADER_LEN`, 3 bytes).
    pub(crate) fn after_header(buf: &'a mut [u8], header_len: usize) -> Result<Self, EncodeError> {
        if buf.len() < header_len {
            return Err(EncodeError::BufferTooSmall {
                needed: header_len,
                capacity: buf.len(),
            });
        }
        Ok(Self {
            buf,
            pos: header_len,
        })
    }

    /// A writer for raw fields from the start of `buf` (no header).
    pub(crate) fn raw(buf: &'a mut [u8]) -> Self {
        Self { buf, pos: 0 }
    }

    pub(crate) fn pos(&self) -> usize {
        self.pos
    }

    pub(crate) fn put(&mut self, b: &[u8]) -> Result<(), EncodeError> {
        let end = self.pos + b.len();
        if end > self.buf.len() {
            return Err(EncodeError::BufferTooSmall {
                needed: end,
                capacity: self.buf.len(),
            });
        }
        self.buf[self.pos..end].copy_from_slice(b);
        self.pos = end;
        Ok(())
    }

    pub(crate) fn u8(&mut self, v: u8) -> Result<(), EncodeError> {
        self.put(&[v])
    }
    pub(crate) fn u16(&mut self, v: u16) -> Result<(), EncodeError> {
        self.put(&v.to_be_bytes())
    }
    pub(crate) fn u32(&mut self, v: u32) -> Result<(), EncodeError> {
        self.put(&v.to_be_bytes())
    }
    pub(crate) fn i32(&mut self, v: i32) -> Result<(), EncodeError> {
        self.put(&v.to_be_bytes())
    }
    pub(crate) fn u64(&mut self, v: u64) -> Result<(), EncodeError> {
        self.put(&v.to_be_bytes())
    }
    pub(crate) fn f64(&mut self, v: f64) -> Result<(), EncodeError> {
        self.put(&v.to_be_bytes())
    }

    pub(crate) fn short_str(&mut self, what: &'static str, s: &str) -> Result<(), EncodeError> {
        let len = s.len();
        let n = u8::try_from(len).map_err(|_| EncodeError::TextTooLong { what, len })?;
        self.u8(n)?;
        self.put(s.as_bytes())
    }

    /// Writes the RTDE header at the start of the buffer for a package ending here; returns the
    /// package length.
    pub(crate) fn finish_package(self, kind: u8) -> Result<usize, EncodeError> {
        let size = u16::try_from(self.pos).map_err(|_| EncodeError::TooLarge(self.pos))?;
        self.buf[0..2].copy_from_slice(&size.to_be_bytes());
        self.buf[2] = kind;
        Ok(self.pos)
    }
}
