//! The storage both controller tables share ([`crate::GainTable`], [`crate::PolicyTable`]): a
//! fixed-size `#[repr(C)]` value of integers and f64 that iceoryx2 moves through shared memory,
//! built zeroed on the heap or in place without a stack temporary, and sealed with an XXH3-64
//! checksum (xxHash 0.8's `XXH3_64bits`, seed 0) of its hashed header fields followed by its
//! hashed values, every value as its IEEE-754 bit pattern, all little-endian, and then its
//! episode plan's bytes when the plan is not the default ([`crate::plan`]). On a
//! little-endian machine that is the raw bytes of those fields. Each table says which header
//! fields and which values are hashed ([`Table::hashed_header`], [`Table::hashed_values`]);
//! the unsafe code of all of them is here.

use core::mem::MaybeUninit;

use xxhash_rust::xxh3::Xxh3;

use crate::layout::{DU, DX};
use crate::plan::EpisodePlan;

/// A controller table's storage (module docs).
///
/// # Safety
///
/// The implementor is `#[repr(C)]` and made of integers and f64 (arrays and structs of them)
/// only: all-zero bytes are a valid value, and any prefix of its bytes may be copied from one
/// value to another.
pub unsafe trait Table: Sized {
    /// The hashed header fields as little-endian bytes, in order.
    type Header: AsRef<[u8]>;

    /// The hashed header fields (their order and widths are the table's wire contract).
    fn hashed_header(&self) -> Self::Header;

    /// The hashed values, after the header.
    fn hashed_values(&self) -> &[f64];

    /// The table's episode plan (hashed after the values unless it is the default).
    fn plan(&self) -> &EpisodePlan;

    /// The stored checksum.
    fn checksum_mut(&mut self) -> &mut u64;

    /// The state and action dimensions, set to [`DX`], [`DU`] in a zeroed table.
    fn dims_mut(&mut self) -> (&mut u32, &mut u32);
}

/// A zeroed `T` on the heap with its dimensions set: one allocation, never the value on the
/// stack.
pub fn new_boxed<T: Table>() -> Box<T> {
    let mut b = Box::<T>::new_uninit();
    init_zeroed(&mut b);
    // SAFETY: init_zeroed initialised every byte.
    unsafe { b.assume_init() }
}

/// Zeroes `slot` in place (e.g. the payload of an iceoryx2 `loan_uninit()` sample), sets the
/// dimensions and returns the initialised table. No allocation, no stack temporary.
pub fn init_zeroed<T: Table>(slot: &mut MaybeUninit<T>) -> &mut T {
    // SAFETY: all-zero bytes are a valid T (the trait's contract).
    let table = unsafe {
        core::ptr::write_bytes(slot.as_mut_ptr(), 0, 1);
        slot.assume_init_mut()
    };
    let (dx, du) = table.dims_mut();
    *dx = DX as u32;
    *du = DU as u32;
    table
}

/// Copies the first `len` bytes of `src` over those of `dst` (a header and the used part of
/// the values: one memcpy, no allocation). Panics if `len` exceeds the table.
pub fn copy_prefix<T: Table>(dst: &mut T, src: &T, len: usize) {
    assert!(len <= core::mem::size_of::<T>(), "a prefix of the table");
    // SAFETY: `dst` and `src` are distinct (one is borrowed mutably), valid and aligned; any
    // prefix of a T's bytes may be copied (the trait's contract).
    unsafe {
        core::ptr::copy_nonoverlapping(
            (src as *const T).cast::<u8>(),
            (dst as *mut T).cast::<u8>(),
            len,
        )
    }
}

/// The checksum of `table`'s current contents (module docs).
pub fn compute_checksum<T: Table>(table: &T) -> u64 {
    let mut h = Xxh3::new();
    h.update(table.hashed_header().as_ref());
    let values = table.hashed_values();
    #[cfg(target_endian = "little")]
    {
        // SAFETY: an f64 slice viewed as bytes; u8 has alignment 1, any initialised memory.
        let bytes =
            unsafe { core::slice::from_raw_parts(values.as_ptr().cast::<u8>(), 8 * values.len()) };
        h.update(bytes);
    }
    #[cfg(target_endian = "big")]
    for v in values {
        h.update(&v.to_bits().to_le_bytes());
    }
    let plan = table.plan();
    if !plan.is_default() {
        h.update(&plan.hashed_bytes());
    }
    h.digest()
}

/// Stores the checksum of `table`'s current contents.
pub fn seal<T: Table>(table: &mut T) {
    let c = compute_checksum(table);
    *table.checksum_mut() = c;
}

/// Little-endian bytes of a header of `N` bytes, written field by field.
pub struct HeaderBytes<const N: usize> {
    bytes: [u8; N],
    at: usize,
}

impl<const N: usize> HeaderBytes<N> {
    /// An empty header.
    pub fn new() -> Self {
        Self {
            bytes: [0; N],
            at: 0,
        }
    }

    /// Appends `v` (8 bytes). Panics past `N` bytes.
    pub fn u64(mut self, v: u64) -> Self {
        self.bytes[self.at..self.at + 8].copy_from_slice(&v.to_le_bytes());
        self.at += 8;
        self
    }

    /// Appends `v` (4 bytes). Panics past `N` bytes.
    pub fn u32(mut self, v: u32) -> Self {
        self.bytes[self.at..self.at + 4].copy_from_slice(&v.to_le_bytes());
        self.at += 4;
        self
    }

    /// The bytes; panics unless exactly `N` were written.
    pub fn finish(self) -> [u8; N] {
        assert_eq!(self.at, N, "the header's length");
        self.bytes
    }
}

impl<const N: usize> Default for HeaderBytes<N> {
    fn default() -> Self {
        Self::new()
    }
}
