//! Step-size adaptation from predicted vs actual improvement (GPS
//! `AlgorithmTrajOpt._stepadjust` and `Algorithm._set_new_mult`).

use crate::error::GpsError;
use crate::policy::lin_gauss::LinGaussPolicy;
use crate::traj_opt::lqr::{TrajInfo, TrajOptLqr};

/// GPS `_set_new_mult`: model the improvement as `I(KL) = pred·KL/KL0 + penalty·KL²` and
/// move to its optimum: `new_mult = pred / (2 max(1e-4, pred − actual))`, clamped to
/// `[0.1, 5]`, applied to `step_mult` and clamped to `[min_step_mult, max_step_mult]`.
pub fn set_new_mult(
    predicted_impr: f64,
    actual_impr: f64,
    step_mult: f64,
    min_step_mult: f64,
    max_step_mult: f64,
) -> f64 {
    let new_mult = predicted_impr / (2.0 * (predicted_impr - actual_impr).max(1e-4));
    let new_mult = new_mult.min(5.0).max(0.1);
    (new_mult * step_mult).min(max_step_mult).max(min_step_mult)
}

/// Laplace objectives and improvements of one step adjustment (vectors' `step_adjust`).
#[derive(Clone, Debug)]
pub struct StepAdjust {
    /// Previous controller under the previous dynamics/cost, per step.
    pub previous_laplace_obj: Vec<f64>,
    /// Current controller under the previous dynamics/cost (what the last update predicted).
    pub new_predicted_laplace_obj: Vec<f64>,
    /// Current controller under the current dynamics/cost (what happened).
    pub new_actual_laplace_obj: Vec<f64>,
    pub predicted_impr: f64,
    pub actual_impr: f64,
    pub step_mult_before: f64,
    pub step_mult_after: f64,
}

/// GPS `_stepadjust`: `prev_pol` was run to get `prev_info`; `cur_pol` (the previous
/// update's result) was run to get `cur_info`.
#[allow(clippy::too_many_arguments)]
pub fn step_adjust(
    opt: &mut TrajOptLqr,
    prev_pol: &LinGaussPolicy,
    prev_info: &TrajInfo,
    cur_pol: &LinGaussPolicy,
    cur_info: &TrajInfo,
    step_mult: f64,
    min_step_mult: f64,
    max_step_mult: f64,
) -> Result<StepAdjust, GpsError> {
    let t = prev_pol.t;
    let mut prev_obj = vec![0.0; t];
    let mut pred_obj = vec![0.0; t];
    let mut act_obj = vec![0.0; t];
    opt.estimate_cost(prev_pol, prev_info, &mut prev_obj)?;
    opt.estimate_cost(cur_pol, prev_info, &mut pred_obj)?;
    opt.estimate_cost(cur_pol, cur_info, &mut act_obj)?;
    let sp: f64 = prev_obj.iter().sum();
    let predicted_impr = sp - pred_obj.iter().sum::<f64>();
    let actual_impr = sp - act_obj.iter().sum::<f64>();
    let after = set_new_mult(
        predicted_impr,
        actual_impr,
        step_mult,
        min_step_mult,
        max_step_mult,
    );
    Ok(StepAdjust {
        previous_laplace_obj: prev_obj,
        new_predicted_laplace_obj: pred_obj,
        new_actual_laplace_obj: act_obj,
        predicted_impr,
        actual_impr,
        step_mult_before: step_mult,
        step_mult_after: after,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn set_new_mult_clamps() {
        // Improvement as predicted -> largest growth (x5), capped by max_step_mult.
        assert_eq!(set_new_mult(1.0, 1.0, 1.0, 0.01, 10.0), 5.0);
        assert_eq!(set_new_mult(1.0, 1.0, 3.0, 0.01, 10.0), 10.0);
        // Worse than nothing -> shrink.
        assert!((set_new_mult(1.0, -2.0, 1.0, 0.01, 10.0) - 1.0 / 6.0).abs() < 1e-15);
        assert_eq!(set_new_mult(0.5, 0.1, 0.011, 0.01, 10.0), 0.01);
    }
}
