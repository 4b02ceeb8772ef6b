//! The controller law, in exactly one place (docs/design.md §1.2; STYLE.md "one home for each fact").
//!
//! ```text
//! a = K_t (s − ŝ_t) + k_t + â_t + L_t ε,     ε ~ N(0, I_dU)
//! ```
//!
//! The real-time loop and the learner's rollouts both call [`controller_action`], so the
//! actions recorded in samples are bit-for-bit what the table prescribes. Noise-free evaluation
//! passes [`NO_NOISE`]. The function is pure, allocation-free and does not panic.

use crate::gains::{GainTable, GAIN_VALUES};
use crate::layout::{MAX_DU, MAX_HORIZON};

/// ε = 0: the noise-free (evaluation) action, i.e. the controller's mean, for any dU (the law
/// reads the first dU entries).
pub const NO_NOISE: [f64; MAX_DU] = [0.0; MAX_DU];

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
    /// The state, noise or action arrays do not have the table's dimensions.
    #[error("the gain table has dX = {dx}, dU = {du}, but the law got a state of {s}, noise of {eps} and an action of {a} entries; the table was made for another task")]
    WrongDimensions {
        /// The table's dX.
        dx: usize,
        /// The table's dU.
        du: usize,
        /// Length of s.
        s: usize,
        /// Length of ε (at least dU is needed).
        eps: usize,
        /// Length of a.
        a: usize,
    },
}

/// `Ok` if `s` has `dx` entries, `eps` at least `du` and `a` exactly `du` (and `dx` is within
/// [`crate::layout::MAX_DX`]): the arrays a controller law of those dimensions reads and writes.
pub(crate) fn check_arrays(
    dx: usize,
    du: usize,
    s: &[f64],
    eps: &[f64],
    a: &[f64],
) -> Result<(), LawError> {
    if s.len() != dx || eps.len() < du || a.len() != du || dx > crate::layout::MAX_DX {
        return Err(LawError::WrongDimensions {
            dx,
            du,
            s: s.len(),
            eps: eps.len(),
            a: a.len(),
        });
    }
    Ok(())
}

/// Writes a = K_t (s − ŝ_t) + k_t + â_t + L_t ε into `a`.
///
/// - `table`: a table that passed [`GainTable::validate`] (this function checks only t and
///   the dimensions).
/// - `t`: time step, 0 ≤ t < T.
/// - `s`: state, dX entries, layout of the table's task ([`crate::layout::StateLayout`]; rad,
///   rad/s, m, m/s).
/// - `eps`: standard-normal noise ε, at least dU entries (the first dU are used); pass
///   [`NO_NOISE`] for the mean action.
/// - `a`: output action, dU entries (rad goal angles, or N·m in torque mode). Left untouched on
///   error.
///
/// Only the lower triangle of L_t is read (j ≤ i), which is all of it for a validated table.
/// The sums run in the same order at every dimension (j ascending), so a table of the
/// reaching task gives the same bits as when its sizes were compile-time constants. The action
/// is finite whenever the table is valid and `s`, `eps` are finite; the caller still clamps it
/// to joint, velocity and effort limits (docs/design.md §2.4).
#[inline]
pub fn controller_action(
    table: &GainTable,
    t: usize,
    s: &[f64],
    eps: &[f64],
    a: &mut [f64],
) -> Result<(), LawError> {
    let horizon = table.horizon();
    let (dx, du) = table.dims();
    let n = table.step_len();
    if t >= horizon || t >= MAX_HORIZON || (t + 1).saturating_mul(n) > GAIN_VALUES {
        return Err(LawError::StepOutOfHorizon {
            t,
            horizon,
            version: table.version,
        });
    }
    check_arrays(dx, du, s, eps, a)?;
    let step = table.step(t);
    let mut ds = [0.0; crate::layout::MAX_DX];
    let ds = &mut ds[..dx];
    for j in 0..dx {
        ds[j] = s[j] - step.s_hat[j];
    }
    for i in 0..du {
        let row = &step.k_mat[i * dx..(i + 1) * dx];
        let mut acc = 0.0;
        for j in 0..dx {
            acc += row[j] * ds[j];
        }
        acc += step.k_vec[i] + step.a_hat[i];
        let l = &step.chol[i * du..(i + 1) * du];
        for j in 0..=i {
            acc += l[j] * eps[j];
        }
        a[i] = acc;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gains::tests::random_table;
    use crate::gains::tests::random_table_for;
    use crate::layout::{StateLayout, DU, DX};
    use nalgebra::{DMatrix, DVector, SMatrix, SVector};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// The law written with nalgebra matrices from the row-major storage.
    fn reference(table: &GainTable, t: usize, s: &[f64; DX], eps: &[f64; DU]) -> [f64; DU] {
        let st = table.step(t);
        let k_mat = SMatrix::<f64, DU, DX>::from_row_slice(st.k_mat);
        let chol = SMatrix::<f64, DU, DU>::from_row_slice(st.chol);
        let s = SVector::<f64, DX>::from_column_slice(s);
        let s_hat = SVector::<f64, DX>::from_column_slice(st.s_hat);
        let a = k_mat * (s - s_hat)
            + SVector::<f64, DU>::from_column_slice(st.k_vec)
            + SVector::<f64, DU>::from_column_slice(st.a_hat)
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
        controller_action(&table, 4, st.s_hat, &NO_NOISE, &mut a).unwrap();
        for i in 0..DU {
            assert_eq!(a[i], st.k_vec[i] + st.a_hat[i]);
        }
        // With noise, the difference from the mean is exactly L ε.
        let eps = [0.3, -1.2, 2.0];
        let mut b = [0.0; DU];
        controller_action(&table, 4, st.s_hat, &eps, &mut b).unwrap();
        let l = |i, j| st.l(i, j);
        let expect = [
            l(0, 0) * eps[0],
            l(1, 0) * eps[0] + l(1, 1) * eps[1],
            l(2, 0) * eps[0] + l(2, 1) * eps[1] + l(2, 2) * eps[2],
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

    /// Any layout: the law against nalgebra's dynamic matrices at dX = 30, dU = 6; arrays of
    /// other sizes are refused, naming both.
    #[test]
    fn any_layout_matches_reference_and_wrong_sizes_are_refused() {
        let layout = StateLayout::POSE6;
        let (dx, du) = (layout.dx(), layout.du());
        let table = random_table_for(&layout, 3, 50);
        let mut rng = ChaCha8Rng::seed_from_u64(12);
        for _ in 0..100 {
            let t = rng.random_range(0..50);
            let s: Vec<f64> = (0..dx).map(|_| rng.random_range(-3.0..3.0)).collect();
            let eps: Vec<f64> = (0..du).map(|_| rng.random_range(-3.0..3.0)).collect();
            let mut a = vec![f64::NAN; du];
            controller_action(&table, t, &s, &eps, &mut a).unwrap();
            let st = table.step(t);
            let r = DMatrix::from_row_slice(du, dx, st.k_mat)
                * (DVector::from_column_slice(&s) - DVector::from_column_slice(st.s_hat))
                + DVector::from_column_slice(st.k_vec)
                + DVector::from_column_slice(st.a_hat)
                + DMatrix::from_row_slice(du, du, st.chol) * DVector::from_column_slice(&eps);
            for i in 0..du {
                assert!((a[i] - r[i]).abs() <= 1e-12 * (1.0 + r[i].abs()));
            }
        }
        let mut a = [7.0; 6];
        let e = controller_action(&table, 0, &[0.0; DX], &NO_NOISE, &mut a).unwrap_err();
        assert_eq!(
            e,
            LawError::WrongDimensions {
                dx: 30,
                du: 6,
                s: 12,
                eps: NO_NOISE.len(),
                a: 6
            }
        );
        assert!(e.to_string().contains("dX = 30, dU = 6"), "{e}");
        assert_eq!(a, [7.0; 6]);
        let mut a3 = [0.0; 3];
        assert!(controller_action(&table, 0, &[0.0; 30], &[0.0; 3], &mut a3).is_err());
    }
}
