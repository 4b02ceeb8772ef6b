//! Generalised advantage estimation (Schulman et al. 2016, eq. 16), as stable-baselines3's
//! `RolloutBuffer.compute_returns_and_advantage` computes it for one episode.

/// Advantages of one episode into `adv` (length `rewards.len()`):
///
/// ```text
/// δ_t = r_t + γ V(s_{t+1}) − V(s_t),   Â_t = δ_t + γλ Â_{t+1},   Â_n = 0
/// ```
///
/// `values[t] = V(s_t)` for the `n` states at which an action was taken; `bootstrap` is
/// `V(s_n)` of the state after the last reward, or 0 if the episode terminated there. Our
/// episodes end by a time limit that the state does not show, so the callers bootstrap (what
/// SB3 does for a time-limit truncation). Returns (the value targets) are `Â_t + V(s_t)`.
pub fn gae(
    rewards: &[f64],
    values: &[f64],
    bootstrap: f64,
    gamma: f64,
    lambda: f64,
    adv: &mut [f64],
) {
    let n = rewards.len();
    assert_eq!(values.len(), n);
    assert_eq!(adv.len(), n);
    let mut last = 0.0;
    for t in (0..n).rev() {
        let next_v = if t + 1 < n { values[t + 1] } else { bootstrap };
        let delta = rewards[t] + gamma * next_v - values[t];
        last = delta + gamma * lambda * last;
        adv[t] = last;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// By hand, γ = 0.5, λ = 0.5 (γλ = 0.25), r = (1, 0, 2), V = (0.5, 1, −1), bootstrap 4:
    /// δ_2 = 2 + 0.5·4 − (−1) = 5, δ_1 = 0 + 0.5·(−1) − 1 = −1.5, δ_0 = 1 + 0.5·1 − 0.5 = 1;
    /// Â_2 = 5, Â_1 = −1.5 + 0.25·5 = −0.25, Â_0 = 1 + 0.25·(−0.25) = 0.9375.
    #[test]
    fn matches_a_hand_computed_example() {
        let mut adv = [0.0; 3];
        gae(&[1.0, 0.0, 2.0], &[0.5, 1.0, -1.0], 4.0, 0.5, 0.5, &mut adv);
        assert_eq!(adv, [0.9375, -0.25, 5.0]);
    }

    /// λ = 1: Â_t + V(s_t) is the discounted return with the bootstrap; λ = 0: the TD error.
    #[test]
    fn limits_are_monte_carlo_and_td() {
        let (r, v) = ([1.0, 2.0, 3.0], [0.3, -0.2, 0.7]);
        let mut adv = [0.0; 3];
        gae(&r, &v, 10.0, 0.9, 1.0, &mut adv);
        let g0 = 1.0 + 0.9 * 2.0 + 0.81 * 3.0 + 0.729 * 10.0;
        assert!((adv[0] + v[0] - g0).abs() < 1e-12);
        gae(&r, &v, 10.0, 0.9, 0.0, &mut adv);
        assert!((adv[1] - (2.0 + 0.9 * 0.7 + 0.2)).abs() < 1e-12);
    }
}
