//! The global policy π_θ(a | s) of MDGPS (docs/design.md §6.1): a Gaussian MLP on the state,
//! one policy for every goal (s[6..9] is ee − goal, so the goal is part of its input).
//!
//! In goal-angle mode (the paper's set-up, docs/design.md §2.3)
//!
//! ```text
//! a = q + μ(u) + σ ⊙ ε,    u = (s − m) ⊘ r,    ε ~ N(0, I_3)
//! ```
//!
//! with q = s[0..3] (rad), μ the PPO baseline's three tanh mean heads
//! ([`GaussianMlpPolicy`], one hand-written MLP per joint, docs/design.md §1.5), m, r (12 each)
//! a fixed input normalisation and σ (rad, 3) a state-independent standard deviation. The
//! offset form makes μ = 0 hold the arm, as the initial controller does (§5 D14). In torque mode
//! a = μ(u) + σ ⊙ ε (N·m).
//!
//! # Flat parameter layout (what a fixed-size table carries)
//! `θ = [m (12) | r (12) | θ_μ0 | θ_μ1 | θ_μ2 | log σ (3)]`, f64, where each `θ_μj` is one head
//! `12 → h_1 → … → h_k → 1` in the MLP's layout (`discriminator::mlp`: layer by layer, `W_l`
//! row-major `n_{l+1} × n_l` then `b_l`). Its length is [`flat_len`]`(hidden)`; with the
//! default `hidden = [64, 64]` that is 24 + 3 · 5057 + 3 = 15,198 values (121.6 KB). The file
//! (`learner::io::policy`) stores this vector and `hidden`.

use rand::Rng;
use ur5_shared::config::ActionMode;
use ur5_shared::layout::{DU, DX};
use ur5_shared::policy::{PolicyTable, PolicyTableError};
use ur5_shared::StateLayout;

use crate::discriminator::Normalizer;
use crate::mlp_policy::{action_base, GaussianMlpPolicy, PolicyWorkspace};
use crate::rollout::{Actors, Policy};

/// Length of the flat parameter vector for mean heads of hidden widths `hidden` (the policy
/// table's layout, [`ur5_shared::policy`]).
pub use ur5_shared::policy::flat_len;

/// The global policy: input normalisation and the Gaussian MLP (module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct GlobalPolicy {
    hidden: Vec<usize>,
    norm: Normalizer,
    net: GaussianMlpPolicy,
}

/// Scratch space of a [`GlobalPolicy`].
#[derive(Clone, Debug)]
pub struct GlobalPolicyWorkspace {
    pub(crate) net: PolicyWorkspace,
    u: [f64; DX],
}

impl GlobalPolicy {
    /// A fresh policy: Glorot weights with a zero output layer (μ = 0: hold the arm), identity
    /// normalisation (set by [`GlobalPolicy::set_normalizer`] before training), σ = `std`.
    pub fn new(hidden: &[usize], std: f64, rng: &mut impl Rng) -> Self {
        Self {
            hidden: hidden.to_vec(),
            norm: Normalizer::identity(DX),
            net: GaussianMlpPolicy::new(hidden, std.ln(), 0.0, rng),
        }
    }

    /// Rebuilds a policy from its hidden widths and flat parameters (module docs); `Err` says
    /// what is wrong (length, non-finite value, non-positive scale).
    pub fn from_flat(hidden: &[usize], flat: &[f64]) -> Result<Self, String> {
        let want = flat_len(DX, DU, hidden);
        if flat.len() != want {
            return Err(format!(
                "{} parameters, hidden widths {hidden:?} need {want}",
                flat.len()
            ));
        }
        if let Some(i) = flat.iter().position(|v| !v.is_finite()) {
            return Err(format!("parameter {i} is not finite ({})", flat[i]));
        }
        let (mean, rest) = flat.split_at(DX);
        let (std, net) = rest.split_at(DX);
        if let Some(i) = std.iter().position(|&v| v <= 0.0) {
            return Err(format!(
                "input scale r[{i}] = {} (parameter {}): must be > 0",
                std[i],
                DX + i
            ));
        }
        let head = (net.len() - DU) / DU;
        let heads = (0..DU)
            .map(|j| net[j * head..(j + 1) * head].to_vec())
            .collect();
        let log_std: [f64; DU] = net[DU * head..].try_into().expect("DU log σ");
        Ok(Self {
            hidden: hidden.to_vec(),
            norm: Normalizer {
                mean: mean.to_vec(),
                std: std.to_vec(),
            },
            net: GaussianMlpPolicy::from_parts(hidden, heads, log_std),
        })
    }

    /// The flat parameter vector (module docs).
    pub fn flat(&self) -> Vec<f64> {
        let mut out = Vec::with_capacity(flat_len(DX, DU, &self.hidden));
        out.extend_from_slice(&self.norm.mean);
        out.extend_from_slice(&self.norm.std);
        let n = self.net.n_params();
        let start = out.len();
        out.resize(start + n, 0.0);
        self.net.read_params(&mut out[start..]);
        out
    }

    /// The policy as a sealed policy table of `version` acting in `mode`, the form the
    /// real-time controller executes ([`ur5_shared::policy`], docs/design.md §3.11). `Err` if
    /// the widths exceed the table's limits.
    pub fn to_table(
        &self,
        version: u64,
        mode: ActionMode,
    ) -> Result<Box<PolicyTable>, PolicyTableError> {
        let mut table = PolicyTable::new_boxed();
        table.fill(
            version,
            &StateLayout::REACH3,
            mode,
            &self.hidden,
            &self.flat(),
        )?;
        Ok(table)
    }

    /// Hidden widths of every mean head.
    pub fn hidden(&self) -> &[usize] {
        &self.hidden
    }

    /// The input normalisation (m, r).
    pub fn normalizer(&self) -> &Normalizer {
        &self.norm
    }

    /// Sets the input normalisation (fitted once, at the first S-step: docs/design.md §6.4).
    pub fn set_normalizer(&mut self, norm: Normalizer) {
        self.norm = norm;
    }

    /// The mean heads over normalised inputs, and log σ.
    pub fn net(&self) -> &GaussianMlpPolicy {
        &self.net
    }

    pub(crate) fn net_mut(&mut self) -> &mut GaussianMlpPolicy {
        &mut self.net
    }

    /// σ (rad in goal-angle mode), per joint.
    pub fn std(&self) -> [f64; DU] {
        self.net.log_std().map(f64::exp)
    }

    /// Scratch space for this policy's size.
    pub fn workspace(&self) -> GlobalPolicyWorkspace {
        GlobalPolicyWorkspace {
            net: self.net.workspace(),
            u: [0.0; DX],
        }
    }

    /// The normalised input u = (s − m) ⊘ r, into `ws`.
    pub(crate) fn normalise(&self, s: &[f64; DX], ws: &mut GlobalPolicyWorkspace) -> [f64; DX] {
        for (i, u) in ws.u.iter_mut().enumerate() {
            *u = (s[i] - self.norm.mean[i]) / self.norm.std[i];
        }
        ws.u
    }

    /// The offset μ(u(s)) (rad; the action mean minus q in goal-angle mode).
    pub fn offset(&self, s: &[f64; DX], ws: &mut GlobalPolicyWorkspace) -> [f64; DU] {
        let u = self.normalise(s, ws);
        self.net.mean(&u, &mut ws.net)
    }

    /// The action mean q + μ(u(s)) (goal-angle mode) or μ(u(s)) (torque mode).
    pub fn mean_action(
        &self,
        s: &[f64; DX],
        mode: ActionMode,
        ws: &mut GlobalPolicyWorkspace,
    ) -> [f64; DU] {
        let mu = self.offset(s, ws);
        let base = action_base(mode, s);
        std::array::from_fn(|j| base[j] + mu[j])
    }

    /// The action mean ā(s) and its Jacobian `∂ā/∂s` (`DU × DX`, action units per state unit):
    /// `∂ā/∂s = E + (∂μ/∂u) diag(1/r)` with E = [I_3 0] in goal-angle mode, 0 in torque mode.
    pub fn mean_action_jacobian(
        &self,
        s: &[f64; DX],
        mode: ActionMode,
        ws: &mut GlobalPolicyWorkspace,
        jac: &mut [[f64; DX]; DU],
    ) -> [f64; DU] {
        let u = self.normalise(s, ws);
        let mu = self.net.mean_jacobian(&u, &mut ws.net, jac);
        for row in jac.iter_mut() {
            for (v, r) in row.iter_mut().zip(&self.norm.std) {
                *v /= r;
            }
        }
        let base = action_base(mode, s);
        if mode == ActionMode::GoalAngles {
            for (j, row) in jac.iter_mut().enumerate() {
                row[ur5_shared::layout::Q.start + j] += 1.0;
            }
        }
        std::array::from_fn(|j| base[j] + mu[j])
    }
}

/// A [`GlobalPolicy`] as a [`Policy`] of the one episode loop: a = ā(s) + σ ⊙ ε (ε = 0 in a
/// noise-free episode). Time-invariant: it acts for any horizon.
pub struct GlobalActor<'a> {
    pol: &'a GlobalPolicy,
    ws: &'a mut GlobalPolicyWorkspace,
    std: [f64; DU],
}

impl<'a> GlobalActor<'a> {
    /// `pol` acting with scratch memory `ws`.
    pub fn new(pol: &'a GlobalPolicy, ws: &'a mut GlobalPolicyWorkspace) -> Self {
        Self {
            std: pol.std(),
            pol,
            ws,
        }
    }
}

impl Policy for GlobalActor<'_> {
    fn horizon(&self) -> usize {
        usize::MAX
    }

    /// The global policy acts on the three-joint task's state (dX = 12, dU = 3); MDGPS
    /// refuses other tasks when it is built.
    fn act(&mut self, _t: usize, s: &[f64], eps: &[f64], mode: ActionMode, out: &mut [f64]) {
        let s: &[f64; DX] = s.try_into().expect("a three-joint task's state");
        let a = self.pol.mean_action(s, mode, self.ws);
        for j in 0..DU {
            out[j] = a[j] + self.std[j] * eps[j];
        }
    }
}

/// A [`GlobalPolicy`]'s episodes in parallel (`crate::rollout::execute`): each actor a
/// [`GlobalActor`] with its own scratch memory. MDGPS, BCO and GAIfO (TD3) run their policies
/// so.
impl Actors for GlobalPolicy {
    fn actor(&self) -> Box<dyn Policy + '_> {
        Box::new(OwnedActor {
            pol: self,
            ws: self.workspace(),
            std: self.std(),
        })
    }
}

/// [`GlobalActor`] owning its scratch memory.
struct OwnedActor<'a> {
    pol: &'a GlobalPolicy,
    ws: GlobalPolicyWorkspace,
    std: [f64; DU],
}

impl Policy for OwnedActor<'_> {
    fn horizon(&self) -> usize {
        usize::MAX
    }

    fn act(&mut self, t: usize, s: &[f64], eps: &[f64], mode: ActionMode, out: &mut [f64]) {
        let mut actor = GlobalActor {
            pol: self.pol,
            ws: &mut self.ws,
            std: self.std,
        };
        actor.act(t, s, eps, mode, out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn flat_layout_round_trips_and_has_the_documented_length() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut p = GlobalPolicy::new(&[64, 64], 0.2, &mut rng);
        // Non-zero output layers so that every head differs.
        let mut flat = p.flat();
        for (i, v) in flat.iter_mut().enumerate().skip(2 * DX) {
            *v += 1e-3 * (i % 7) as f64;
        }
        p = GlobalPolicy::from_flat(&[64, 64], &flat).unwrap();
        assert_eq!(flat_len(DX, DU, &[64, 64]), 15_198);
        assert_eq!(p.flat(), flat);
        let e = GlobalPolicy::from_flat(&[64, 64], &flat[1..]).unwrap_err();
        assert!(e.contains("15197 parameters") && e.contains("15198"), "{e}");
        let mut bad = flat.clone();
        bad[DX + 2] = 0.0;
        let e = GlobalPolicy::from_flat(&[64, 64], &bad).unwrap_err();
        assert!(e.contains("r[2]"), "{e}");
    }

    /// The controller's `policy_action` on the table gives the learner's action bit for bit,
    /// noisy and noise-free, in both action modes and for several shapes.
    #[test]
    fn the_policy_table_acts_bit_for_bit_as_the_learner() {
        use rand::Rng;
        use ur5_shared::policy::{policy_action, PolicyBounds, PolicyScratch};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut scratch = PolicyScratch::default();
        for hidden in [vec![64, 64], vec![7], vec![5, 9, 3]] {
            let p = GlobalPolicy::new(&hidden, 0.3, &mut rng);
            let mut flat = p.flat();
            for v in flat.iter_mut() {
                *v += rng.random_range(-0.3..0.3);
            }
            for v in &mut flat[DX..2 * DX] {
                *v = rng.random_range(0.2..3.0);
            }
            let p = GlobalPolicy::from_flat(&hidden, &flat).unwrap();
            let mut ws = p.workspace();
            for mode in [ActionMode::GoalAngles, ActionMode::Torque] {
                let table = p.to_table(4, mode).unwrap();
                table.validate(&PolicyBounds::default()).unwrap();
                for k in 0..50 {
                    let s: [f64; DX] = std::array::from_fn(|_| rng.random_range(-2.0..2.0));
                    let eps: [f64; DU] = if k % 2 == 0 {
                        [0.0; DU]
                    } else {
                        std::array::from_fn(|_| rng.random_range(-2.0..2.0))
                    };
                    let mut want = [f64::NAN; DU];
                    GlobalActor::new(&p, &mut ws).act(0, &s, &eps, mode, &mut want);
                    let mut got = [f64::NAN; DU];
                    policy_action(&table, &s, &eps, &mut scratch, &mut got).unwrap();
                    assert_eq!(
                        got.map(f64::to_bits),
                        want.map(f64::to_bits),
                        "{hidden:?} {mode:?}"
                    );
                }
            }
        }
    }
}
