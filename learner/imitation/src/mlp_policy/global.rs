//! The global policy π_θ(a | s) of MDGPS (docs/design.md §6.1), also BCO's cloned policy and
//! GAIfO (TD3)'s actor: a Gaussian MLP on the normalised state, one policy for every goal (the
//! tool points minus their targets are in the state, so the goal is part of its input). Its dimensions are its task's layout ([`StateLayout`]: dX
//! inputs, dU joints), fixed when it is built.
//!
//! In goal-angle mode (the paper's set-up, docs/design.md §2.3)
//!
//! ```text
//! a = q + μ(u) + σ ⊙ ε,    u = (s − m) ⊘ r,    ε ~ N(0, I_dU)
//! ```
//!
//! with q the joint angles (rad, the layout's `q()`), μ the PPO baseline's dU tanh mean heads
//! ([`GaussianMlpPolicy`], one hand-written MLP per joint, docs/design.md §1.5), m, r (dX each)
//! a fixed input normalisation and σ (rad, dU) a state-independent standard deviation. The
//! offset form makes μ = 0 hold the arm, as the initial controller does (§5 D14). In torque mode
//! a = μ(u) + σ ⊙ ε (N·m).
//!
//! # Flat parameter layout (what a fixed-size table carries)
//! `θ = [m (dX) | r (dX) | θ_μ0 | … | θ_μ(dU−1) | log σ (dU)]`, f64, where each `θ_μj` is one
//! head `dX → h_1 → … → h_k → 1` in the MLP's layout (`discriminator::mlp`: layer by layer,
//! `W_l` row-major `n_{l+1} × n_l` then `b_l`). Its length is [`flat_len`]`(dX, dU, hidden)`;
//! with the default `hidden = [64, 64]` that is 24 + 3 · 5057 + 3 = 15,198 values (121.6 KB) at
//! three joints and a point (dX = 12), 60 + 6 · 6209 + 6 = 37,320 at six joints and a pose
//! (dX = 30). The file (`learner::io::policy`) stores this vector, `hidden` and the layout's
//! names.

use rand::Rng;
use ur5_shared::config::ActionMode;
use ur5_shared::joints::Joints;
use ur5_shared::policy::{PolicyTable, PolicyTableError};
use ur5_shared::StateLayout;

use super::{action_base, GaussianMlpPolicy, PolicyWorkspace};
use crate::discriminator::Normalizer;
use crate::rollout::{Actors, Policy};

/// Length of the flat parameter vector for mean heads of hidden widths `hidden` (the policy
/// table's layout, [`ur5_shared::policy`]).
pub use ur5_shared::policy::flat_len;

/// The global policy: input normalisation and the Gaussian MLP (module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct GlobalPolicy {
    layout: StateLayout,
    hidden: Vec<usize>,
    norm: Normalizer,
    net: GaussianMlpPolicy,
}

/// Scratch space of a [`GlobalPolicy`].
#[derive(Clone, Debug)]
pub struct GlobalPolicyWorkspace {
    pub(crate) net: PolicyWorkspace,
    /// The normalised input u of the last [`GlobalPolicy::normalise`] (dX).
    pub(crate) u: Vec<f64>,
}

impl GlobalPolicy {
    /// A fresh policy: Glorot weights with a zero output layer (μ = 0: hold the arm), identity
    /// normalisation (set by [`GlobalPolicy::set_normalizer`] before training), σ = `std`, for
    /// the task of `layout`.
    pub fn new(layout: StateLayout, hidden: &[usize], std: f64, rng: &mut impl Rng) -> Self {
        let (dx, du) = (layout.dx(), layout.du());
        Self {
            layout,
            hidden: hidden.to_vec(),
            norm: Normalizer::identity(dx),
            net: GaussianMlpPolicy::new(dx, du, hidden, std.ln(), 0.0, rng),
        }
    }

    /// Rebuilds a policy for the task of `layout` from its hidden widths and flat parameters
    /// (module docs); `Err` says what is wrong (length, non-finite value, non-positive scale).
    pub fn from_flat(layout: StateLayout, hidden: &[usize], flat: &[f64]) -> Result<Self, String> {
        let (dx, du) = (layout.dx(), layout.du());
        let want = flat_len(dx, du, hidden);
        if flat.len() != want {
            return Err(format!(
                "{} parameters, hidden widths {hidden:?} need {want} (dX = {dx}, dU = {du}: \
                 {layout})",
                flat.len()
            ));
        }
        if let Some(i) = flat.iter().position(|v| !v.is_finite()) {
            return Err(format!("parameter {i} is not finite ({})", flat[i]));
        }
        let (mean, rest) = flat.split_at(dx);
        let (std, net) = rest.split_at(dx);
        if let Some(i) = std.iter().position(|&v| v <= 0.0) {
            return Err(format!(
                "input scale r[{i}] = {} (parameter {}): must be > 0",
                std[i],
                dx + i
            ));
        }
        let head = (net.len() - du) / du;
        let heads = (0..du)
            .map(|j| net[j * head..(j + 1) * head].to_vec())
            .collect();
        let log_std = Joints::from_slice(&net[du * head..]);
        Ok(Self {
            layout,
            hidden: hidden.to_vec(),
            norm: Normalizer {
                mean: mean.to_vec(),
                std: std.to_vec(),
            },
            net: GaussianMlpPolicy::from_parts(dx, hidden, heads, log_std),
        })
    }

    /// The flat parameter vector (module docs).
    pub fn flat(&self) -> Vec<f64> {
        let mut out =
            Vec::with_capacity(flat_len(self.layout.dx(), self.layout.du(), &self.hidden));
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
        table.fill(version, &self.layout, mode, &self.hidden, &self.flat())?;
        Ok(table)
    }

    /// The layout of the task the policy acts on (its dX inputs and dU outputs).
    pub fn layout(&self) -> StateLayout {
        self.layout
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
    pub fn std(&self) -> Joints {
        let mut std = *self.net.log_std();
        for v in std.iter_mut() {
            *v = v.exp();
        }
        std
    }

    /// Scratch space for this policy's size.
    pub fn workspace(&self) -> GlobalPolicyWorkspace {
        GlobalPolicyWorkspace {
            net: self.net.workspace(),
            u: vec![0.0; self.layout.dx()],
        }
    }

    /// The normalised input u = (s − m) ⊘ r (dX), into `ws.u`.
    pub(crate) fn normalise(&self, s: &[f64], ws: &mut GlobalPolicyWorkspace) {
        assert_eq!(s.len(), ws.u.len(), "a state of the policy's dX");
        for (i, u) in ws.u.iter_mut().enumerate() {
            *u = (s[i] - self.norm.mean[i]) / self.norm.std[i];
        }
    }

    /// The offset μ(u(s)) (rad; the action mean minus q in goal-angle mode), dU.
    pub fn offset(&self, s: &[f64], ws: &mut GlobalPolicyWorkspace) -> Joints {
        self.normalise(s, ws);
        self.net.mean(&ws.u, &mut ws.net)
    }

    /// The action mean q + μ(u(s)) (goal-angle mode) or μ(u(s)) (torque mode), dU.
    pub fn mean_action(
        &self,
        s: &[f64],
        mode: ActionMode,
        ws: &mut GlobalPolicyWorkspace,
    ) -> Joints {
        let mu = self.offset(s, ws);
        let mut a = action_base(mode, self.layout.du(), s);
        for (a, m) in a.iter_mut().zip(mu.iter()) {
            *a += m;
        }
        a
    }

    /// The action mean ā(s) and its Jacobian `∂ā/∂s` (`dU × dX` row-major, action units per
    /// state unit): `∂ā/∂s = E + (∂μ/∂u) diag(1/r)` with E = [I_dU 0] (the joint angles) in
    /// goal-angle mode, 0 in torque mode.
    pub fn mean_action_jacobian(
        &self,
        s: &[f64],
        mode: ActionMode,
        ws: &mut GlobalPolicyWorkspace,
        jac: &mut [f64],
    ) -> Joints {
        self.normalise(s, ws);
        let mu = self.net.mean_jacobian(&ws.u, &mut ws.net, jac);
        let dx = self.layout.dx();
        for row in jac.chunks_exact_mut(dx) {
            for (v, r) in row.iter_mut().zip(&self.norm.std) {
                *v /= r;
            }
        }
        let mut a = action_base(mode, self.layout.du(), s);
        if mode == ActionMode::GoalAngles {
            let q = self.layout.q();
            for (j, row) in jac.chunks_exact_mut(dx).enumerate() {
                row[q.start + j] += 1.0;
            }
        }
        for (a, m) in a.iter_mut().zip(mu.iter()) {
            *a += m;
        }
        a
    }
}

/// A [`GlobalPolicy`] as a [`Policy`] of the one episode loop: a = ā(s) + σ ⊙ ε (ε = 0 in a
/// noise-free episode). Time-invariant: it acts for any horizon.
pub struct GlobalActor<'a> {
    pol: &'a GlobalPolicy,
    ws: &'a mut GlobalPolicyWorkspace,
    std: Joints,
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

    /// The global policy acts on states of its layout's dX and writes its dU actions.
    fn act(&mut self, _t: usize, s: &[f64], eps: &[f64], mode: ActionMode, out: &mut [f64]) {
        let a = self.pol.mean_action(s, mode, self.ws);
        for j in 0..a.len() {
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
    std: Joints,
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
    use ur5_shared::layout::{DU, DX};

    #[test]
    fn flat_layout_round_trips_and_has_the_documented_length() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut p = GlobalPolicy::new(StateLayout::REACH3, &[64, 64], 0.2, &mut rng);
        // Non-zero output layers so that every head differs.
        let mut flat = p.flat();
        for (i, v) in flat.iter_mut().enumerate().skip(2 * DX) {
            *v += 1e-3 * (i % 7) as f64;
        }
        p = GlobalPolicy::from_flat(StateLayout::REACH3, &[64, 64], &flat).unwrap();
        assert_eq!(flat_len(DX, DU, &[64, 64]), 15_198);
        assert_eq!(p.flat(), flat);
        let e = GlobalPolicy::from_flat(StateLayout::REACH3, &[64, 64], &flat[1..]).unwrap_err();
        assert!(e.contains("15197 parameters") && e.contains("15198"), "{e}");
        let mut bad = flat.clone();
        bad[DX + 2] = 0.0;
        let e = GlobalPolicy::from_flat(StateLayout::REACH3, &[64, 64], &bad).unwrap_err();
        assert!(e.contains("r[2]"), "{e}");
        // Six joints and a pose: the documented length, and a three-joint vector is refused
        // naming both dimensions.
        let pose = StateLayout::POSE6;
        assert_eq!(flat_len(pose.dx(), pose.du(), &[64, 64]), 37_320);
        let p6 = GlobalPolicy::new(pose, &[64, 64], 0.2, &mut rng);
        let f6 = p6.flat();
        assert_eq!(f6.len(), 37_320);
        assert_eq!(GlobalPolicy::from_flat(pose, &[64, 64], &f6).unwrap(), p6);
        let e = GlobalPolicy::from_flat(pose, &[64, 64], &flat).unwrap_err();
        assert!(
            e.contains("15198 parameters") && e.contains("dX = 30"),
            "{e}"
        );
    }

    /// The controller's `policy_action` on the table gives the learner's action bit for bit,
    /// noisy and noise-free, in both action modes and for several shapes.
    #[test]
    fn the_policy_table_acts_bit_for_bit_as_the_learner() {
        use rand::Rng;
        use ur5_shared::policy::{policy_action, PolicyBounds, PolicyScratch};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut scratch = PolicyScratch::default();
        for (layout, hidden) in [
            (StateLayout::REACH3, vec![64, 64]),
            (StateLayout::REACH3, vec![7]),
            (StateLayout::REACH3, vec![5, 9, 3]),
            (StateLayout::POSE6, vec![16, 8]),
        ] {
            let (dx, du) = (layout.dx(), layout.du());
            let p = GlobalPolicy::new(layout, &hidden, 0.3, &mut rng);
            let mut flat = p.flat();
            for v in flat.iter_mut() {
                *v += rng.random_range(-0.3..0.3);
            }
            for v in &mut flat[dx..2 * dx] {
                *v = rng.random_range(0.2..3.0);
            }
            let p = GlobalPolicy::from_flat(layout, &hidden, &flat).unwrap();
            let mut ws = p.workspace();
            for mode in [ActionMode::GoalAngles, ActionMode::Torque] {
                let table = p.to_table(4, mode).unwrap();
                table.validate(&PolicyBounds::default()).unwrap();
                table.check_layout(&layout).unwrap();
                for k in 0..50 {
                    let s: Vec<f64> = (0..dx).map(|_| rng.random_range(-2.0..2.0)).collect();
                    let eps: Vec<f64> = if k % 2 == 0 {
                        vec![0.0; du]
                    } else {
                        (0..du).map(|_| rng.random_range(-2.0..2.0)).collect()
                    };
                    let mut want = vec![f64::NAN; du];
                    GlobalActor::new(&p, &mut ws).act(0, &s, &eps, mode, &mut want);
                    let mut got = vec![f64::NAN; du];
                    policy_action(&table, &s, &eps, &mut scratch, &mut got).unwrap();
                    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                    assert_eq!(bits(&got), bits(&want), "{layout} {hidden:?} {mode:?}");
                }
            }
        }
    }
}
