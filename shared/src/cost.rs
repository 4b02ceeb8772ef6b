//! Task cost of a trajectory and normalised performance (docs/design.md §1.6, the paper's §5).
//!
//! ```text
//! C(τ) = d_n + Σ_{i=0..n} (i/n) d_i,    d_i = ‖ee_i − goal‖ (m),  n = T − 1
//! (a pose goal: d_i = ‖(e_1, e_2, e_3)‖, the three tool points' errors together)
//! ```
//!
//! over the T states of an episode: the final distance counts twice, earlier distances with a
//! weight rising linearly from 0, so reaching early and staying there is cheapest. Units: m.
//!
//! Normalised performance `(C_random − C) / (C_random − C_expert)` is 0 for the average random
//! policy and 1 for the expert (higher is better; it may leave [0, 1]).
//!
//! Degenerate inputs are errors, never a silent number: fewer than 2 states (n = 0 makes i/n
//! undefined), a non-finite distance, or C_random == C_expert (the scale is undefined).
//! Nothing here allocates.

use crate::layout::{StateLayout, DX, EE_MINUS_GOAL};

/// Why a cost could not be computed.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum CostError {
    /// Fewer than 2 states.
    #[error("task cost needs at least 2 states (n = T − 1 ≥ 1), got {len}")]
    TooShort {
        /// Number of states given.
        len: usize,
    },
    /// A distance (or the position it came from) is NaN or infinite.
    #[error("task cost: distance d_{index} = {value} is not finite")]
    NonFinite {
        /// State index i.
        index: usize,
        /// The distance.
        value: f64,
    },
    /// An input to the normalisation is not finite.
    #[error("normalised performance: non-finite input (C = {cost}, C_random = {random}, C_expert = {expert})")]
    NonFiniteNormalisation {
        /// C.
        cost: f64,
        /// C_random.
        random: f64,
        /// C_expert.
        expert: f64,
    },
    /// C_random == C_expert: random and expert are indistinguishable, the scale is undefined.
    #[error("normalised performance undefined: C_random = C_expert = {0}; the expert is no better than random")]
    DegenerateNormalisation(f64),
}

/// C(τ) from the distances d_0..d_n (m).
pub fn task_cost_from_distances(d: &[f64]) -> Result<f64, CostError> {
    task_cost_iter(d.iter().copied(), d.len())
}

/// C(τ) from end-effector positions (m, arm base frame) and the goal (m, same frame).
pub fn task_cost(ee: &[[f64; 3]], goal: &[f64; 3]) -> Result<f64, CostError> {
    task_cost_iter(ee.iter().map(|p| distance(p, goal)), ee.len())
}

/// C(τ) from state vectors (layout of [`crate::layout`]): d_i = ‖s_i[EE_MINUS_GOAL]‖.
pub fn task_cost_from_states(states: &[[f64; DX]]) -> Result<f64, CostError> {
    let d = states.iter().map(|s| {
        let e = &s[EE_MINUS_GOAL];
        norm3(e[0], e[1], e[2])
    });
    task_cost_iter(d, states.len())
}

/// The distance d of state `s` (layout `layout`) to the goal (m): the norm of every tool
/// point's position minus its target together, ‖(e_1, …, e_p)‖ (GPS's `CostFK` on several
/// points); for a point goal ‖ee − goal‖.
pub fn goal_distance(layout: &StateLayout, s: &[f64]) -> f64 {
    let mut d2 = 0.0;
    for v in &s[layout.points()] {
        d2 += v * v;
    }
    d2.sqrt()
}

/// C(τ) from the states `x` ((T, dX) row-major, layout `layout`): d_i = [`goal_distance`].
pub fn task_cost_of_states(layout: &StateLayout, x: &[f64]) -> Result<f64, CostError> {
    let dx = layout.dx();
    let d = x.chunks_exact(dx).map(|s| goal_distance(layout, s));
    task_cost_iter(d, x.len() / dx)
}

fn distance(p: &[f64; 3], goal: &[f64; 3]) -> f64 {
    norm3(p[0] - goal[0], p[1] - goal[1], p[2] - goal[2])
}

fn norm3(x: f64, y: f64, z: f64) -> f64 {
    (x * x + y * y + z * z).sqrt()
}

fn task_cost_iter(d: impl Iterator<Item = f64>, len: usize) -> Result<f64, CostError> {
    if len < 2 {
        return Err(CostError::TooShort { len });
    }
    let n = (len - 1) as f64;
    let mut sum = 0.0;
    let mut last = 0.0;
    for (i, di) in d.enumerate() {
        if !di.is_finite() {
            return Err(CostError::NonFinite {
                index: i,
                value: di,
            });
        }
        sum += (i as f64 / n) * di;
        last = di;
    }
    Ok(last + sum)
}

/// (C_random − C) / (C_random − C_expert): 0 = average random policy, 1 = expert.
///
/// Errors if any input is non-finite or C_random == C_expert. If the expert is worse than
/// random (C_expert > C_random) the formula is still applied, so better than the expert is
/// still > 1 and worse than random < 0.
pub fn normalised_performance(cost: f64, c_random: f64, c_expert: f64) -> Result<f64, CostError> {
    if !(cost.is_finite() && c_random.is_finite() && c_expert.is_finite()) {
        return Err(CostError::NonFiniteNormalisation {
            cost,
            random: c_random,
            expert: c_expert,
        });
    }
    let scale = c_random - c_expert;
    if scale == 0.0 {
        return Err(CostError::DegenerateNormalisation(c_random));
    }
    Ok((c_random - cost) / scale)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hand_computed_costs() {
        // n = 1: C = d_1 + (0·d_0 + 1·d_1) = 2 d_1.
        assert_eq!(task_cost_from_distances(&[5.0, 3.0]), Ok(6.0));
        // n = 2: C = d_2 + 0·d_0 + 0.5·d_1 + 1·d_2 = 1 + 1 + 1 = 3.
        assert_eq!(task_cost_from_distances(&[9.0, 2.0, 1.0]), Ok(3.0));
        // n = 4, d = 4,3,2,1,0: weights 0, .25, .5, .75, 1 → 0 + .75 + 1 + .75 + 0 = 2.5.
        assert_eq!(
            task_cost_from_distances(&[4.0, 3.0, 2.0, 1.0, 0.0]),
            Ok(2.5)
        );
        // Constant distance d over T = 101 states: d + d·Σ i/100 = d + 50.5 d.
        let c = task_cost_from_distances(&[0.2; 101]).unwrap();
        assert!((c - 51.5 * 0.2).abs() < 1e-12);
    }

    #[test]
    fn positions_and_states_give_the_same_cost() {
        let goal = [0.5, 0.0, 0.25];
        // Distances 5 (3-4-0 triangle), 1, 0.
        let ee = [[3.5, 4.0, 0.25], [0.5, 1.0, 0.25], goal];
        // n = 2: 0 + 0.5·1 + 0 + d_2 (0) = 0.5.
        assert_eq!(task_cost(&ee, &goal), Ok(0.5));
        let states: Vec<[f64; DX]> = ee
            .iter()
            .map(|p| crate::layout::state_vector(&[0.0; 3], &[0.0; 3], p, &[0.0; 3], &goal))
            .collect();
        assert_eq!(task_cost_from_states(&states), Ok(0.5));
    }

    #[test]
    fn degenerate_trajectories_are_errors() {
        assert_eq!(
            task_cost_from_distances(&[]),
            Err(CostError::TooShort { len: 0 })
        );
        assert_eq!(
            task_cost_from_distances(&[1.0]),
            Err(CostError::TooShort { len: 1 })
        );
        assert_eq!(
            task_cost(&[], &[0.0; 3]),
            Err(CostError::TooShort { len: 0 })
        );
        let err = task_cost_from_distances(&[1.0, f64::INFINITY, 0.0]).unwrap_err();
        assert_eq!(
            err,
            CostError::NonFinite {
                index: 1,
                value: f64::INFINITY
            }
        );
        assert!(err.to_string().contains("d_1"));
    }

    #[test]
    fn normalisation() {
        assert_eq!(normalised_performance(10.0, 10.0, 2.0), Ok(0.0));
        assert_eq!(normalised_performance(2.0, 10.0, 2.0), Ok(1.0));
        assert_eq!(normalised_performance(6.0, 10.0, 2.0), Ok(0.5));
        assert_eq!(normalised_performance(14.0, 10.0, 2.0), Ok(-0.5));
        assert_eq!(normalised_performance(1.0, 10.0, 2.0), Ok(1.125));
        assert_eq!(
            normalised_performance(1.0, 3.0, 3.0),
            Err(CostError::DegenerateNormalisation(3.0))
        );
        assert!(matches!(
            normalised_performance(f64::NAN, 3.0, 1.0),
            Err(CostError::NonFiniteNormalisation { .. })
        ));
    }
}
