//! The controller law, in exactly one place (docs/design.md §1.2; STYLE.md "one home for each fact").
//!
//! ```text
//! a = K_t (s − ŝ_t) + k_t + â_t + L_t ε,     ε ~ N(0, I_dU)
//! ```
//!
//! The real-time loop and the learner's rollouts both call [`controller_action`], so the
//! actions recorded in samples are bit-for-bit what the table prescribes. Noise-free evaluation
//! passes [`NO_NOISE`]. The function is pure, allocation-free and does not panic.

use crate::gains::GainTable;
use crate::layout::{DU, DX, MAX_HORIZON};

/// ε = 0: the noise-free (evaluation) action, i.e. the controller's mean.
pub const NO_NOISE: [f64; DU] = [0.0; DU];

/// Why no action was computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum LawError {
    /// t is not a step of the table (t ≥ T). The episode ran longer than the table.
    #[error("time step t = {t} is outside the gain table's horizon T = {horizon} (table version {version}); end the episode at T or publish a longer table")]
    StepOutOfHorizon {
        /// Requested step.
        t: usize,
        /// The table's horizon.
        horizon: usize,
        /// The table's version.
        version: u64,
    },
}

/// Writes a = K_t (s − ŝ_t) + k_t + â_t + L_t ε into `a`.
///
/// - `table`: a table that passed [`GainTable::validate`] (this function checks only t).
/// - `t`: time step, 0 ≤ t < T.
/// - `s`: state, layout of [`crate::layout`] (rad, rad/s, m, m/s).
/// - `eps`: standard-normal noise ε, dU; pass [`NO_NOISE`] for the mean action.
/// - `a`: output action, dU (rad goal angles, or N·m in torque mode). Left untouched on error.
///
/// Only the lower triangle of L_t is read (j ≤ i), which is all of it for a validated table.
/// The action is finite whenever the table is valid and `s`, `eps` are finite; the caller
/// still clamps it to joint, velocity and effort limits (docs/design.md §2.4).
#[inline]
pub fn controller_action(
    table: &GainTable,
    t: usize,
    s: &[f64; DX],
    eps: &[f64; DU],
    a: &mut [f64; DU],
) -> Result<(), LawError> {
    let horizon = table.horizon();
    if t >= horizon || t >= MAX_HORIZON {
        return Err(LawError::StepOutOfHorizon {
            t,
            horizon,
            version: table.version,
        });
    }
    let step = &table.steps[t];
    let mut ds = [0.0; DX];
    for j in 0..DX {
        ds[j] = s[j] - step.s_hat[j];
    }
    for i in 0..DU {
        let mut acc = 0.0;
        for j in 0..DX {
            acc += step.k_mat[i][j] * ds[j];
        }
        acc += step.k_vec[i] + step.a_hat[i];
        for j in 0..=i {
            acc += step.chol[i][j] * eps[j];
        }
        a[i] = acc;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gains::tests::random_table;
    use nalgebra::{SMatrix, SVector};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// The law written with nalgebra matrices from the row-major storage.
    fn reference(table: &GainTable, t: usize, s: &[f64; DX], eps: &[f64; DU]) -> [f64; DU] {
        let st = table.step(t);
        let k_mat = SMatrix::<f64, DU, DX>::from_row_slice(st.k_mat.as_flattened());
        let chol = SMatrix::<f64, DU, DU>::from_row_slice(st.chol.as_flattened());
        let s = SVector::<f64, DX>::from_column_slice(s);
        let s_hat = SVector::<f64, DX>::from_column_slice(&st.s_hat);
        let a = k_mat * (s - s_hat)
            + SVector::<f64, DU>::from_column_slice(&st.k_vec)
            + SVector::<f64, DU>::from_column_slice(&st.a_hat)
            + chol * SVector::<f64, DU>::from_column_slice(eps);
        a.into()
    }

    #[test]
    fn matches_reference_on_random_tables() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for seed in 0..20 {
            let table = random_table(seed, 100);
            for _ in 0..50 {
                let t = rng.random_range(0..100);
                let s: [f64; DX] = core::array::from_fn(|_| rng.random_range(-3.0..3.0));
                let eps: [f64; DU] = core::array::from_fn(|_| rng.random_range(-3.0..3.0));
                let mut a = [f64::NAN; DU];
                controller_action(&table, t, &s, &eps, &mut a).unwrap();
                let r = reference(&table, t, &s, &eps);
                for i in 0..DU {
                    let tol = 1e-12 * (1.0 + r[i].abs());
                    assert!(
                        (a[i] - r[i]).abs() <= tol,
                        "t={t} i={i}: {} vs {}",
                        a[i],
                        r[i]
                    );
                }
            }
        }
    }

    #[test]
    fn noise_free_action_is_the_mean_and_nominal_state_gives_nominal_action() {
        let table = random_table(5, 10);
        let st = table.step(4);
        let mut a = [0.0; DU];
        controller_action(&table, 4, &st.s_hat, &NO_NOISE, &mut a).unwrap();
        for i in 0..DU {
            assert_eq!(a[i], st.k_vec[i] + st.a_hat[i]);
        }
        // With noise, the difference from the mean is exactly L ε.
        let eps = [0.3, -1.2, 2.0];
        let mut b = [0.0; DU];
        controller_action(&table, 4, &st.s_hat, &eps, &mut b).unwrap();
        let l = &st.chol;
        let expect = [
            l[0][0] * eps[0],
            l[1][0] * eps[0] + l[1][1] * eps[1],
            l[2][0] * eps[0] + l[2][1] * eps[1] + l[2][2] * eps[2],
        ];
        for i in 0..DU {
            assert!((b[i] - a[i] - expect[i]).abs() < 1e-12);
        }
    }

    #[test]
    fn rejects_steps_outside_the_horizon_and_leaves_output_alone() {
        let table = random_table(5, 10);
        let mut a = [7.0; DU];
        let err = controller_action(&table, 10, &[0.0; DX], &NO_NOISE, &mut a).unwrap_err();
        assert_eq!(
            err,
            LawError::StepOutOfHorizon {
                t: 10,
                horizon: 10,
                version: 6
            }
        );
        assert_eq!(a, [7.0; DU]);
        // A corrupt horizon beyond MAX_HORIZON must not index out of the table.
        let mut bad = random_table(5, 10);
        bad.horizon = u32::MAX;
        assert!(controller_action(&bad, MAX_HORIZON, &[0.0; DX], &NO_NOISE, &mut a).is_err());
    }
}
