//! The costs the KL-bounded LQR step optimises, as GPS has them: a cost object that expands
//! around a batch of samples into the per-sample (l, lx, lu, lxx, luu, lux) of GPS's
//! `cost.eval` ([`Cost`]), plugged into the one LQR iteration
//! ([`crate::iteration::LqrIteration`]). The expert's is the true task cost ([`task`]);
//! LQR+GAIfO's is the critic's composite cost C_t(s, a) = D(s, F_t [s; a] + f_t) ([`composite`];
//! docs/design.md §1, steps 4–5); a demonstrations' per-step tracking term can be added to it
//! ([`tracking`], docs/design.md §5 D39).

pub mod composite;
pub mod task;
pub mod tracking;

use gps::algorithm::eval_cost::CostDerivs;
use gps::dynamics::Dynamics;

use crate::rollout::Episode;

/// A cost that expands to second order around samples.
pub trait Cost {
    /// Fills `out` (resized to N episodes × T steps, GPS layout) with the cost and its
    /// derivatives around each step's executed (s, a) of each of `episodes`. `dynamics` is the
    /// model fitted on those episodes this iteration (a cost of the predicted next state needs
    /// it; the task cost does not).
    fn expand(&mut self, episodes: &[Episode], dynamics: &Dynamics, out: &mut CostDerivs);

    /// GPS `cs`: the cost each of `episodes` incurred at each step, `(N, T)` into `out`; what
    /// PILQR's PI2 step weighs. `derivs` is this cost's [`Cost::expand`] around the same
    /// episodes; its `l` is the cost at each executed (s, a), which is the sampled cost of a
    /// cost of (s, a) alone (this default).
    fn sampled(&mut self, episodes: &[Episode], derivs: &CostDerivs, out: &mut Vec<f64>) {
        let _ = episodes;
        out.clear();
        out.extend_from_slice(&derivs.l);
    }
}
