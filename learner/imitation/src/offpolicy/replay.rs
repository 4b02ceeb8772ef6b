//! The replay buffer of off-policy GAIfO: every transition the arm made, up to a fixed
//! capacity (the oldest overwritten first), sampled uniformly with the learner's seeded RNG.
//!
//! A row is `(s, a, s', kind)`: s and s' states of the task's layout (dX each), a the action
//! offset the arm executed, normalised by the per-step action bound (dU, in [−1, 1]; module
//! docs of [`super`]), and [`RowKind`] the DAC handling of its end (Kostrikov et al. 2019,
//! §4.2). No reward is stored: it is the critic's `−D(s, s')`, recomputed for every minibatch
//! from the critic of the moment, as DAC does.
//!
//! Rows are kept in insertion order in a ring: row `i` of [`ReplayBuffer::row`] is the i-th
//! oldest. The snapshot ([`ReplayBuffer::snapshot`]) stores the rows in that order, so a
//! restored buffer samples the same rows for the same RNG.

use gps::snapshot::Snapshot;
use rand::Rng;

use crate::ImitationError;

/// How a row's episode continues after s' (DAC's absorbing states, Kostrikov et al. 2019).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RowKind {
    /// s' is a state the policy acts in next: the TD target bootstraps from Q'(s', π'(s')).
    /// Also the last transition of an episode cut by the time limit (the reaching tasks'
    /// every episode), which DAC treats as not terminal.
    Step,
    /// The episode terminated at s': the TD target bootstraps from the absorbing state,
    /// Q'(s_a, 0).
    ToAbsorbing,
    /// The absorbing state's own transition s_a → s_a (s, s' hold the terminal state, whose
    /// standing still gives the reward); the target is `r + γ Q'(s_a, 0)`.
    Absorbing,
}

impl RowKind {
    fn code(self) -> u64 {
        match self {
            RowKind::Step => 0,
            RowKind::ToAbsorbing => 1,
            RowKind::Absorbing => 2,
        }
    }

    fn from_code(c: u64) -> Option<Self> {
        match c {
            0 => Some(RowKind::Step),
            1 => Some(RowKind::ToAbsorbing),
            2 => Some(RowKind::Absorbing),
            _ => None,
        }
    }
}

/// One stored transition, borrowed from the buffer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Row<'a> {
    /// s, dX.
    pub s: &'a [f64],
    /// Normalised action offset, dU.
    pub a: &'a [f64],
    /// s', dX.
    pub s_next: &'a [f64],
    /// How the episode continues.
    pub kind: RowKind,
}

/// A ring of at most `capacity` transitions (module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct ReplayBuffer {
    dx: usize,
    du: usize,
    capacity: usize,
    /// Slot the next row is written to.
    head: usize,
    len: usize,
    /// Rows ever added (the oldest row is number `added − len`).
    added: u64,
    s: Vec<f64>,
    a: Vec<f64>,
    s_next: Vec<f64>,
    kind: Vec<RowKind>,
}

const S: &str = "replay.s";
const A: &str = "replay.a";
const S_NEXT: &str = "replay.s_next";
const KIND: &str = "replay.kind";
const ADDED: &str = "replay.added";

impl ReplayBuffer {
    /// An empty buffer for states of `dx` and actions of `du` entries holding at most
    /// `capacity` rows (≥ 1). Memory grows with the rows, up to `capacity`.
    pub fn new(dx: usize, du: usize, capacity: usize) -> Self {
        assert!(capacity >= 1 && dx >= 1 && du >= 1);
        Self {
            dx,
            du,
            capacity,
            head: 0,
            len: 0,
            added: 0,
            s: Vec::new(),
            a: Vec::new(),
            s_next: Vec::new(),
            kind: Vec::new(),
        }
    }

    /// Rows held.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether it holds no row.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Most rows held.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// Rows ever added.
    pub fn added(&self) -> u64 {
        self.added
    }

    /// Adds a row, overwriting the oldest when full.
    pub fn push(&mut self, s: &[f64], a: &[f64], s_next: &[f64], kind: RowKind) {
        assert_eq!(
            (s.len(), a.len(), s_next.len()),
            (self.dx, self.du, self.dx)
        );
        if self.len < self.capacity {
            self.s.extend_from_slice(s);
            self.a.extend_from_slice(a);
            self.s_next.extend_from_slice(s_next);
            self.kind.push(kind);
            self.len += 1;
        } else {
            let (i, dx, du) = (self.head, self.dx, self.du);
            self.s[i * dx..(i + 1) * dx].copy_from_slice(s);
            self.a[i * du..(i + 1) * du].copy_from_slice(a);
            self.s_next[i * dx..(i + 1) * dx].copy_from_slice(s_next);
            self.kind[i] = kind;
        }
        self.head = (self.head + 1) % self.capacity;
        self.added += 1;
    }

    /// The slot of the i-th oldest row.
    fn slot(&self, i: usize) -> usize {
        assert!(i < self.len, "row {i} of {}", self.len);
        if self.len < self.capacity {
            i
        } else {
            (self.head + i) % self.capacity
        }
    }

    /// The i-th oldest row.
    pub fn row(&self, i: usize) -> Row<'_> {
        let k = self.slot(i);
        let (dx, du) = (self.dx, self.du);
        Row {
            s: &self.s[k * dx..(k + 1) * dx],
            a: &self.a[k * du..(k + 1) * du],
            s_next: &self.s_next[k * dx..(k + 1) * dx],
            kind: self.kind[k],
        }
    }

    /// `out` filled with `batch` row numbers (for [`Self::row`]) drawn uniformly with
    /// replacement from `rng`, one `random_range` each.
    pub fn sample(&self, rng: &mut impl Rng, batch: usize, out: &mut Vec<usize>) {
        assert!(!self.is_empty(), "sampling an empty replay buffer");
        out.clear();
        out.extend((0..batch).map(|_| rng.random_range(0..self.len)));
    }

    /// The rows in order, oldest first (`replay.s`, `replay.a`, `replay.s_next`: (len, d);
    /// `replay.kind`: codes 0 step, 1 to absorbing, 2 absorbing; `replay.added`).
    pub fn snapshot(&self, out: &mut Snapshot) {
        let (mut s, mut a, mut n) = (Vec::new(), Vec::new(), Vec::new());
        let mut kind = Vec::with_capacity(self.len);
        for i in 0..self.len {
            let r = self.row(i);
            s.extend_from_slice(r.s);
            a.extend_from_slice(r.a);
            n.extend_from_slice(r.s_next);
            kind.push(r.kind.code());
        }
        out.put(S, &[self.len, self.dx], &s);
        out.put(A, &[self.len, self.du], &a);
        out.put(S_NEXT, &[self.len, self.dx], &n);
        out.put_words(KIND, &kind);
        out.put_words(ADDED, &[self.added]);
    }

    /// Rebuilds the buffer of [`Self::snapshot`] in `snap`: the same rows in the same order,
    /// so the same samples for the same RNG. Refused (naming the entry) if the rows do not fit
    /// this buffer's dimensions and capacity or are not finite.
    pub fn restore(&mut self, snap: &Snapshot) -> Result<(), ImitationError> {
        let bad = |what: String| ImitationError::Checkpoint(format!("replay buffer: {what}"));
        let (shape, s) = snap.real_any(S).map_err(|e| bad(e.to_string()))?;
        let len = shape.first().copied().unwrap_or(0);
        if shape != [len, self.dx] || len > self.capacity {
            return Err(bad(format!(
                "{S} has shape {shape:?}, expected (rows ≤ {}, {})",
                self.capacity, self.dx
            )));
        }
        let a = snap
            .real(A, &[len, self.du])
            .map_err(|e| bad(e.to_string()))?;
        let n = snap
            .real(S_NEXT, &[len, self.dx])
            .map_err(|e| bad(e.to_string()))?;
        let kind = snap.words(KIND, len).map_err(|e| bad(e.to_string()))?;
        let added = snap.words(ADDED, 1).map_err(|e| bad(e.to_string()))?[0];
        if added < len as u64 {
            return Err(bad(format!("{ADDED} = {added} < {len} rows")));
        }
        if s.iter().chain(a).chain(n).any(|v| !v.is_finite()) {
            return Err(bad("non-finite values".into()));
        }
        let mut fresh = Self::new(self.dx, self.du, self.capacity);
        for i in 0..len {
            let k = RowKind::from_code(kind[i])
                .ok_or_else(|| bad(format!("{KIND}[{i}] = {} is not 0, 1 or 2", kind[i])))?;
            let (dx, du) = (self.dx, self.du);
            fresh.push(
                &s[i * dx..(i + 1) * dx],
                &a[i * du..(i + 1) * du],
                &n[i * dx..(i + 1) * dx],
                k,
            );
        }
        fresh.added = added;
        *self = fresh;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn push_n(b: &mut ReplayBuffer, from: usize, n: usize) {
        for i in from..from + n {
            let v = i as f64;
            b.push(&[v, v + 0.5], &[-v], &[v + 1.0, v + 1.5], RowKind::Step);
        }
    }

    #[test]
    fn holds_the_newest_capacity_rows_oldest_first_after_wrapping() {
        let mut b = ReplayBuffer::new(2, 1, 4);
        push_n(&mut b, 0, 3);
        assert_eq!((b.len(), b.added()), (3, 3));
        assert_eq!(b.row(0).s, &[0.0, 0.5]);
        push_n(&mut b, 3, 3);
        assert_eq!((b.len(), b.capacity(), b.added()), (4, 4, 6));
        let firsts: Vec<f64> = (0..4).map(|i| b.row(i).s[0]).collect();
        assert_eq!(firsts, [2.0, 3.0, 4.0, 5.0]);
        let r = b.row(3);
        assert_eq!((r.a, r.s_next), (&[-5.0][..], &[6.0, 6.5][..]));
        // Wrapping again, past a whole capacity.
        push_n(&mut b, 6, 9);
        let firsts: Vec<f64> = (0..4).map(|i| b.row(i).s[0]).collect();
        assert_eq!(firsts, [11.0, 12.0, 13.0, 14.0]);
    }

    #[test]
    fn sampling_is_uniform_seeded_and_survives_the_snapshot() {
        let mut b = ReplayBuffer::new(2, 1, 5);
        push_n(&mut b, 0, 7);
        b.push(&[1.0, 2.0], &[0.0], &[1.0, 2.0], RowKind::Absorbing);
        let draw = |b: &ReplayBuffer, seed| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let mut idx = Vec::new();
            b.sample(&mut rng, 5000, &mut idx);
            idx
        };
        let idx = draw(&b, 3);
        assert_eq!(idx, draw(&b, 3), "same seed, same rows");
        assert_ne!(idx, draw(&b, 4), "another seed, other rows");
        // Every row drawn about 1/5 of the time (5000 draws: σ ≈ 28 per row).
        for r in 0..5 {
            let c = idx.iter().filter(|&&i| i == r).count();
            assert!((850..1150).contains(&c), "row {r}: {c}");
        }
        let mut snap = Snapshot::default();
        b.snapshot(&mut snap);
        let mut c = ReplayBuffer::new(2, 1, 5);
        c.restore(&snap).unwrap();
        assert_eq!(draw(&c, 3), idx);
        for i in 0..5 {
            assert_eq!(c.row(i), b.row(i));
        }
        assert_eq!(c.added(), 8);
        assert_eq!(c.row(4).kind, RowKind::Absorbing);
        // And the restored ring continues as the original does.
        push_n(&mut b, 20, 3);
        push_n(&mut c, 20, 3);
        for i in 0..5 {
            assert_eq!(c.row(i), b.row(i));
        }
    }

    #[test]
    fn a_snapshot_of_other_dimensions_or_capacity_is_refused() {
        let mut b = ReplayBuffer::new(2, 1, 5);
        push_n(&mut b, 0, 4);
        let mut snap = Snapshot::default();
        b.snapshot(&mut snap);
        let e = ReplayBuffer::new(3, 1, 5).restore(&snap).unwrap_err();
        assert!(e.to_string().contains("replay.s"), "{e}");
        let e = ReplayBuffer::new(2, 1, 3).restore(&snap).unwrap_err();
        assert!(e.to_string().contains("rows ≤ 3"), "{e}");
        let mut bad = snap.clone();
        bad.put_words(KIND, &[0, 0, 7, 0]);
        let e = ReplayBuffer::new(2, 1, 5).restore(&bad).unwrap_err();
        assert!(e.to_string().contains("replay.kind[2] = 7"), "{e}");
    }
}
