//! A vector of per-joint values (angles in rad, velocities in rad/s, efforts in N·m) whose
//! length is the task's number of active joints, fixed when a configuration is read: 3 with
//! the wrist locked, 6 for the whole arm (docs/design.md §2.1). `Copy`, no heap, capacity
//! [`MAX_JOINTS`], so the real-time loop can hold it; it reads and writes as a slice
//! (`Deref<Target = [f64]>`) and serialises as a plain sequence, so a three-joint
//! configuration reads and writes (and hashes) as it did when these were arrays of three.

use std::fmt;
use std::ops::{Deref, DerefMut};

use serde::{Deserialize, Deserializer, Serialize, Serializer};

use crate::layout::MAX_JOINTS;

/// Values of 1 to [`MAX_JOINTS`] joints, in joint order (shoulder pan first). Entries past
/// the length are kept at zero, so equality compares the values alone.
#[derive(Clone, Copy, PartialEq)]
pub struct Joints {
    n: usize,
    v: [f64; MAX_JOINTS],
}

/// A joint vector of a length no task has.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{0} joint values: a task has 1 to {MAX_JOINTS} joints (3 with the wrist locked, 6 for the whole arm)")]
pub struct JointCount(pub usize);

impl Joints {
    /// The values of `v`, or [`JointCount`] if it has none or more than [`MAX_JOINTS`].
    pub fn try_from_slice(v: &[f64]) -> Result<Self, JointCount> {
        if v.is_empty() || v.len() > MAX_JOINTS {
            return Err(JointCount(v.len()));
        }
        let mut out = Self {
            n: v.len(),
            v: [0.0; MAX_JOINTS],
        };
        out.v[..v.len()].copy_from_slice(v);
        Ok(out)
    }

    /// The values of `v`; panics on a length no task has (a programming error: use
    /// [`Joints::try_from_slice`] on input).
    pub fn from_slice(v: &[f64]) -> Self {
        Self::try_from_slice(v).expect("1 to MAX_JOINTS values")
    }

    /// `n` copies of `x`.
    pub fn splat(n: usize, x: f64) -> Self {
        Self::from_slice(&[x; MAX_JOINTS][..n])
    }

    /// These values followed by `more` (e.g. the three arm joints and the wrist's three).
    pub fn extended(&self, more: &[f64]) -> Result<Self, JointCount> {
        let n = self.n + more.len();
        if n > MAX_JOINTS {
            return Err(JointCount(n));
        }
        let mut out = *self;
        out.v[self.n..n].copy_from_slice(more);
        out.n = n;
        Ok(out)
    }

    /// The values as a slice.
    pub fn as_slice(&self) -> &[f64] {
        &self.v[..self.n]
    }

    /// The values as a mutable slice.
    pub fn as_mut_slice(&mut self) -> &mut [f64] {
        &mut self.v[..self.n]
    }
}

impl Deref for Joints {
    type Target = [f64];
    fn deref(&self) -> &[f64] {
        self.as_slice()
    }
}

impl DerefMut for Joints {
    fn deref_mut(&mut self) -> &mut [f64] {
        self.as_mut_slice()
    }
}

impl AsRef<[f64]> for Joints {
    fn as_ref(&self) -> &[f64] {
        self.as_slice()
    }
}

impl<const N: usize> From<[f64; N]> for Joints {
    /// Panics unless 1 ≤ N ≤ [`MAX_JOINTS`] (array lengths are written in the code).
    fn from(v: [f64; N]) -> Self {
        Self::from_slice(&v)
    }
}

impl<const N: usize> PartialEq<[f64; N]> for Joints {
    fn eq(&self, other: &[f64; N]) -> bool {
        self.as_slice() == other.as_slice()
    }
}

impl fmt::Debug for Joints {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.as_slice().fmt(f)
    }
}

impl Serialize for Joints {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        self.as_slice().serialize(s)
    }
}

impl<'de> Deserialize<'de> for Joints {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let v = Vec::<f64>::deserialize(d)?;
        Self::try_from_slice(&v).map_err(serde::de::Error::custom)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, serde::Serialize, serde::Deserialize)]
    struct T {
        q: Joints,
    }

    #[test]
    fn serialises_as_a_plain_sequence_and_refuses_bad_lengths() {
        let j = Joints::from([0.0, -2.0, 2.4]);
        assert_eq!(
            toml::to_string(&T { q: j }).unwrap(),
            "q = [0.0, -2.0, 2.4]\n"
        );
        let back: T = toml::from_str("q = [0.0, -2.0, 2.4]").unwrap();
        assert_eq!(back.q, j);
        assert_eq!(back.q, [0.0, -2.0, 2.4]);
        let e = toml::from_str::<T>("q = []").unwrap_err().to_string();
        assert!(e.contains("0 joint values"), "{e}");
        let e = toml::from_str::<T>("q = [1,2,3,4,5,6,7,8]")
            .unwrap_err()
            .to_string();
        assert!(e.contains("8 joint values"), "{e}");
    }

    #[test]
    fn extends() {
        let j = Joints::from([1.0, 2.0, 3.0]);
        let six = j.extended(&[4.0, 5.0, 6.0]).unwrap();
        assert_eq!(six.len(), 6);
        assert_eq!(six, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        assert_eq!(six.extended(&[0.0, 0.0]), Err(JointCount(8)));
        assert_eq!(Joints::splat(2, 7.0), [7.0, 7.0]);
        // Entries past the length stay zero, so equality is of the values alone.
        let mut three = six;
        three.n = 3;
        three.v[3..].fill(0.0);
        assert_eq!(three, j);
    }
}
