//! Plain CDR (OMG CDR as XCDR1, what ROS 2 Humble and Jazzy put on the wire): a 4-byte
//! encapsulation header (`00 01 00 00` little-endian, `00 00 00 00` big-endian), then the fields
//! in declaration order, each primitive aligned to its size (at most 8) counted from the end of
//! the header; a string is a u32 length including its NUL, the bytes and the NUL; a sequence a
//! u32 count and its elements. No trailing padding is written (CycloneDDS writes none either;
//! readers ignore padding after the last field).

/// Encapsulation identifier of little-endian plain CDR (RTPS 2.5 Table 10.3, `CDR_LE`).
pub const CDR_LE: [u8; 2] = [0x00, 0x01];
/// Encapsulation identifier of big-endian plain CDR (`CDR_BE`).
pub const CDR_BE: [u8; 2] = [0x00, 0x00];

/// Why a CDR message could not be read.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CdrError {
    /// Fewer bytes than the message needs.
    #[error("CDR message truncated: {needed} more bytes needed at offset {at}")]
    Truncated { at: usize, needed: usize },
    /// An encapsulation other than plain CDR (e.g. XCDR2 or parameter lists).
    #[error("unsupported CDR encapsulation {0:02x?} (plain CDR, 00 00 or 00 01, expected)")]
    Encapsulation([u8; 2]),
    /// A string without its terminating NUL, or not UTF-8.
    #[error("malformed CDR string at offset {at}")]
    BadString { at: usize },
    /// A sequence longer than the reader accepts.
    #[error("CDR sequence of {len} elements at offset {at} exceeds the limit of {max}")]
    SequenceTooLong { at: usize, len: usize, max: usize },
}

/// Longest sequence the decoders accept, so that a corrupt count cannot make them allocate
/// gigabytes; far above any message here (a joint state has one entry per joint).
pub const MAX_SEQUENCE: usize = 1 << 16;

/// Appends a little-endian CDR message to a byte vector (reused between messages: clear
/// it, then encode; once it has grown to the largest message, encoding allocates nothing).
pub struct CdrWriter<'a> {
    buf: &'a mut Vec<u8>,
    origin: usize,
}

impl<'a> CdrWriter<'a> {
    /// Starts a message at the end of `buf`: writes the `CDR_LE` encapsulation header.
    pub fn new(buf: &'a mut Vec<u8>) -> Self {
        buf.extend_from_slice(&[CDR_LE[0], CDR_LE[1], 0, 0]);
        let origin = buf.len();
        Self { buf, origin }
    }

    fn align(&mut self, n: usize) {
        let pos = self.buf.len() - self.origin;
        let pad = (n - pos % n) % n;
        self.buf.extend(core::iter::repeat_n(0u8, pad));
    }

    pub fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }
    pub fn i8(&mut self, v: i8) {
        self.buf.push(v as u8);
    }
    pub fn u32(&mut self, v: u32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    pub fn i32(&mut self, v: i32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    pub fn u64(&mut self, v: u64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    pub fn f64(&mut self, v: f64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    pub fn string(&mut self, s: &str) {
        self.u32(s.len() as u32 + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }
    /// A sequence's count (the elements follow, written by the caller).
    pub fn count(&mut self, n: usize) {
        self.u32(n as u32);
    }
    pub fn f64_seq(&mut self, v: &[f64]) {
        self.count(v.len());
        for &x in v {
            self.f64(x);
        }
    }
    pub fn string_seq<S: AsRef<str>>(&mut self, v: &[S]) {
        self.count(v.len());
        for s in v {
            self.string(s.as_ref());
        }
    }
}

/// Reads a plain CDR message of either byte order.
pub struct CdrReader<'a> {
    body: &'a [u8],
    pos: usize,
    little: bool,
}

impl<'a> CdrReader<'a> {
    /// Checks the encapsulation header and positions the reader on the first field.
    pub fn new(msg: &'a [u8]) -> Result<Self, CdrError> {
        if msg.len() < 4 {
            return Err(CdrError::Truncated {
                at: 0,
                needed: 4 - msg.len(),
            });
        }
        Self::from_body([msg[0], msg[1]], &msg[4..])
    }

    /// A reader of a body whose encapsulation identifier `id` was read elsewhere (by DDS).
    pub fn from_body(id: [u8; 2], body: &'a [u8]) -> Result<Self, CdrError> {
        let little = match id {
            CDR_LE => true,
            CDR_BE => false,
            _ => return Err(CdrError::Encapsulation(id)),
        };
        Ok(Self {
            body,
            pos: 0,
            little,
        })
    }

    fn take<const N: usize>(&mut self) -> Result<[u8; N], CdrError> {
        let pad = (N - self.pos % N) % N;
        let start = self.pos + pad;
        let end = start + N;
        if end > self.body.len() {
            return Err(CdrError::Truncated {
                at: start + 4,
                needed: end - self.body.len(),
            });
        }
        self.pos = end;
        let mut b = [0u8; N];
        b.copy_from_slice(&self.body[start..end]);
        if !self.little {
            b.reverse();
        }
        Ok(b)
    }

    pub fn u8(&mut self) -> Result<u8, CdrError> {
        Ok(self.take::<1>()?[0])
    }
    pub fn i8(&mut self) -> Result<i8, CdrError> {
        Ok(self.take::<1>()?[0] as i8)
    }
    pub fn u32(&mut self) -> Result<u32, CdrError> {
        Ok(u32::from_le_bytes(self.take()?))
    }
    pub fn i32(&mut self) -> Result<i32, CdrError> {
        Ok(i32::from_le_bytes(self.take()?))
    }
    pub fn u64(&mut self) -> Result<u64, CdrError> {
        Ok(u64::from_le_bytes(self.take()?))
    }
    pub fn f64(&mut self) -> Result<f64, CdrError> {
        Ok(f64::from_le_bytes(self.take()?))
    }

    /// A sequence's count, refused above `MAX_SEQUENCE` or above what the bytes left can hold
    /// (`min_size` bytes per element).
    pub fn count(&mut self, min_size: usize) -> Result<usize, CdrError> {
        let at = self.pos + 4;
        let len = self.u32()? as usize;
        let left = self.body.len() - self.pos;
        if len > MAX_SEQUENCE || len.saturating_mul(min_size) > left {
            return Err(CdrError::SequenceTooLong {
                at,
                len,
                max: MAX_SEQUENCE.min(left / min_size.max(1)),
            });
        }
        Ok(len)
    }

    /// A string, borrowed from the message.
    pub fn str(&mut self) -> Result<&'a str, CdrError> {
        let at = self.pos + 4;
        let n = self.u32()? as usize;
        if n == 0 || self.pos + n > self.body.len() {
            return Err(CdrError::BadString { at });
        }
        let bytes = &self.body[self.pos..self.pos + n];
        self.pos += n;
        if bytes[n - 1] != 0 {
            return Err(CdrError::BadString { at });
        }
        core::str::from_utf8(&bytes[..n - 1]).map_err(|_| CdrError::BadString { at })
    }

    pub fn f64_seq(&mut self) -> Result<Vec<f64>, CdrError> {
        let n = self.count(8)?;
        (0..n).map(|_| self.f64()).collect()
    }

    pub fn string_seq(&mut self) -> Result<Vec<String>, CdrError> {
        let n = self.count(5)?;
        (0..n).map(|_| self.str().map(str::to_owned)).collect()
    }
}
