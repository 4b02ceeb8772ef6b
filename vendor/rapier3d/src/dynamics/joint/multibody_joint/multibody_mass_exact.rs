//! **Added for hil-sim (not in upstream rapier 0.36.1; see `vendor/rapier3d/PATCHED.md`).**
//!
//! `Multibody::update_mass_matrix_exact`: the two augmented mass matrices of upstream's
//! `update_mass_matrix` (before its damping, armature and spring terms), bit for bit, without
//! nalgebra's dynamic `quadform`/`gemm` calls, their allocations, and the products with
//! structural zeros.
//!
//! Why the bits cannot change. Every entry of both matrices is built, link after link, as
//! `out ← dot + out`, starting from `+0`, where `dot` is nalgebra's dot product over the six
//! rows of a body Jacobian column: `res = +0; res += a₀b₀; …; res += a₅b₅`. Hence:
//! 1. `out` and `res` are never `−0` (a sum is `−0` only when both terms are), so adding a
//!    zero of either sign leaves them unchanged: a product with a zero factor may be dropped
//!    from a dot, and a dot that is `+0` may be skipped.
//! 2. Intermediate values (the columns of `M·J`, the Coriolis matrices) therefore only matter
//!    up to the sign of their zeros, and `+`, `−`, `×` of finite values map values equal up to
//!    the sign of zero to values equal up to the sign of zero: so the product of a finite value
//!    and a structural zero may be dropped from any intermediate sum.
//! 3. The structural zeros: the off-diagonal blocks of the 6×6 rigid-body mass matrix, and the
//!    columns of link `i`'s body Jacobian and Coriolis matrices beyond its last ancestor dof
//!    (`assembly_id + ndofs`; they are `+0` because upstream only ever adds finite multiples of
//!    `+0` to them). So link `i` touches the leading `active × active` block only.
//! 4. The nonzero products are formed in nalgebra's order: `gemv`/`gemm` columns as
//!    `y ← (α·a)·x + y`, one column of `a` after the other; dots row after row.
//!
//! These steps need every factor of a dropped product to be finite. They are checked: the
//! inputs and small matrices explicitly, the computed intermediates through the outputs
//! (a non-finite intermediate reaches an output). When a check fails, the function returns
//! `false` and the caller runs upstream's code.

use super::Multibody;
use crate::alloc_prelude::*;
use crate::dynamics::RigidBodySet;
use crate::math::{DIM, Real, SPATIAL_DIM, SimdAngVector};
use crate::utils::{AngularInertiaOps, CrossProduct, CrossProductMatrix, IndexMut2, vect_to_na};
use na::{DMatrix, Dyn, Matrix3, OMatrix, SMatrix};

type Mat3 = Matrix3<Real>;

/// `y[:, c] ← (α·a)·x[:, c] + y[:, c]` for the columns `c < ncols`, as nalgebra's `gemm` with
/// `beta = 1` computes each column: `y_r ← (α·a_r0)·x_0 + y_r`, then columns 1 and 2 of `a`.
/// `y` and `x` are column-major with column strides `ys` and `xs`, starting at row 0 of the
/// rows used.
#[inline(always)]
fn gemm3(y: &mut [Real], ys: usize, alpha: Real, a: &Mat3, x: &[Real], xs: usize, ncols: usize) {
    for c in 0..ncols {
        let xc = &x[c * xs..c * xs + 3];
        let yc = &mut y[c * ys..c * ys + 3];
        for j in 0..3 {
            let xj = xc[j];
            for r in 0..3 {
                yc[r] = (alpha * a[(r, j)]) * xj + yc[r];
            }
        }
    }
}

/// Bit 31 set when a value of `s` is not finite (exponent all ones): OR-reduced over the
/// slice with integer operations only, so that the check vectorises.
#[inline(always)]
fn nonfinite(s: &[Real]) -> u32 {
    s.iter().fold(0, |acc, v| {
        acc | (v.to_bits() & 0x7f80_0000).wrapping_add(0x0080_0000)
    })
}

/// The columns of a column-major matrix with six rows.
#[inline(always)]
fn cols6(m: &[Real]) -> &[[Real; 6]] {
    m.as_chunks::<6>().0
}

#[inline(always)]
fn nonfinite3(v: crate::math::Vector) -> u32 {
    nonfinite(&[v.x, v.y, v.z])
}

impl Multibody {
    /// Upstream's mass-matrix assembly (see the module doc): `true` when done, `false` (and
    /// the matrices to be rebuilt by upstream's code) when a value it relies on is not finite.
    pub(super) fn update_mass_matrix_exact(&mut self, dt: Real, bodies: &RigidBodySet) -> bool {
        let n = self.ndofs;
        if self.augmented_mass.ncols() != n {
            self.augmented_mass = DMatrix::zeros(n, n);
            self.acc_augmented_mass = DMatrix::zeros(n, n);
        } else {
            self.augmented_mass.fill(0.0);
            self.acc_augmented_mass.fill(0.0);
        }
        self.augmented_mass_indices.clear();

        let coriolis_ndofs = self.coriolis_v.first().map(|m| m.ncols());
        if self.coriolis_v.len() != self.links.len() || coriolis_ndofs != Some(n) {
            self.coriolis_v = vec![OMatrix::<Real, na::U3, Dyn>::zeros(n); self.links.len()];
            self.coriolis_w = vec![OMatrix::<Real, na::U3, Dyn>::zeros(n); self.links.len()];
            self.i_coriolis_dt = crate::math::Jacobian::zeros(n);
        }

        // Bit 31: a value the skipped products rely on is not finite.
        let mut bad = nonfinite(&[dt]);
        let mut curr_assembly_id = 0;
        // M·J columns of the current link: without and with the gyroscopic term.
        let mut w0 = [0.0 as Real; SPATIAL_DIM];
        let mut w1 = [0.0 as Real; SPATIAL_DIM];

        for i in 0..self.links.len() {
            let link = &self.links[i];
            let rb = &bodies[link.rigid_body];
            let rb_mass = rb.mprops.effective_mass();
            let rb_inertia = rb.mprops.effective_angular_inertia().into_matrix();
            let link_ndofs = link.joint.ndofs();

            assert_eq!(
                curr_assembly_id, link.assembly_id,
                "Internal error: contiguity assumption on assembly_id does not hold."
            );
            curr_assembly_id += link_ndofs;

            if link.joint.kinematic {
                for k in link.assembly_id..link.assembly_id + link_ndofs {
                    self.augmented_mass_indices.remove(k);
                }
            } else {
                for k in link.assembly_id..link.assembly_id + link_ndofs {
                    self.augmented_mass_indices.keep(k);
                }
            }

            let gyroscopic_matrix = rb.vels.angvel.gcross_matrix() * rb_inertia
                - (rb_inertia * rb.vels.angvel).gcross_matrix();
            let mut augmented_inertia = rb_inertia;
            augmented_inertia += gyroscopic_matrix * dt;
            let m0 = super::concat_rb_mass_matrix(rb_mass, rb_inertia.into());
            let m1 = super::concat_rb_mass_matrix(rb_mass, augmented_inertia.into());
            bad |= nonfinite(m0.as_slice()) | nonfinite(m1.as_slice());

            // Columns beyond the last ancestor dof are +0 in every matrix of this link.
            let active = link.assembly_id + link_ndofs;

            /*
             * Coriolis matrices (upstream's order of operations, active columns only).
             */
            let rb_j = self.body_jacobians[i].as_slice();
            bad |= nonfinite(&rb_j[..SPATIAL_DIM * active]);
            let angvel_cross = SimdAngVector::<Real>::from(rb.vels.angvel).gcross_matrix();
            bad |= nonfinite3(rb.vels.angvel)
                | nonfinite3(link.shift02)
                | nonfinite3(link.shift23)
                | nonfinite3(link.joint_velocity.linvel)
                | nonfinite3(link.joint_velocity.angvel);

            if i != 0 {
                let parent_id = link.parent_internal_id;
                let parent_link = &self.links[parent_id];
                let parent_rb = &bodies[parent_link.rigid_body];
                let parent_active = parent_link.assembly_id + parent_link.joint.ndofs();
                let parent_j = self.body_jacobians[parent_id].as_slice();
                let parent_j_w = &parent_j[DIM..];
                let parent_w = SimdAngVector::<Real>::from(parent_rb.vels.angvel).gcross_matrix();

                let shift_cross_tr = vect_to_na(link.shift02).gcross_matrix_tr();
                let dvel_cross = vect_to_na(
                    rb.vels.angvel.gcross(link.shift02) + 2.0 * link.joint_velocity.linvel,
                )
                .gcross_matrix_tr();
                let linvel_cross = vect_to_na(link.joint_velocity.linvel).gcross_matrix_tr();
                let parent_w_shift = parent_w * shift_cross_tr;
                let vel_wrt_joint_w = vect_to_na(link.joint_velocity.angvel).gcross_matrix();
                bad |= nonfinite(parent_w.as_slice())
                    | nonfinite(shift_cross_tr.as_slice())
                    | nonfinite(dvel_cross.as_slice())
                    | nonfinite(linvel_cross.as_slice())
                    | nonfinite(parent_w_shift.as_slice())
                    | nonfinite(vel_wrt_joint_w.as_slice());

                let (coriolis_v, parent_coriolis_v) = self.coriolis_v.index_mut2(i, parent_id);
                let (coriolis_w, parent_coriolis_w) = self.coriolis_w.index_mut2(i, parent_id);
                coriolis_v.copy_from(parent_coriolis_v);
                coriolis_w.copy_from(parent_coriolis_w);
                let cv = coriolis_v.as_mut_slice();
                let cw = coriolis_w.as_mut_slice();
                let pcw = parent_coriolis_w.as_slice();

                gemm3(cv, 3, 1.0, &shift_cross_tr, pcw, 3, parent_active);
                gemm3(cv, 3, 1.0, &dvel_cross, parent_j_w, 6, parent_active);
                gemm3(cv, 3, 1.0, &linvel_cross, parent_j_w, 6, parent_active);
                gemm3(cv, 3, 1.0, &parent_w_shift, parent_j_w, 6, parent_active);
                gemm3(cw, 3, -1.0, &vel_wrt_joint_w, parent_j_w, 6, parent_active);

                if !link.joint.kinematic {
                    let mut tmp1 = SMatrix::<Real, SPATIAL_DIM, SPATIAL_DIM>::zeros();
                    let mut rb_joint_j = tmp1.columns_mut(0, link_ndofs);
                    link.joint.jacobian(
                        &(parent_link.local_to_world.rotation
                            * link.joint.data.local_frame1.rotation),
                        &mut rb_joint_j,
                    );
                    let jj = tmp1.as_slice();
                    bad |= nonfinite(&jj[..SPATIAL_DIM * link_ndofs]);
                    let own = 3 * link.assembly_id;
                    gemm3(&mut cv[own..], 3, 2.0, &parent_w, jj, 6, link_ndofs);
                    gemm3(&mut cw[own..], 3, 1.0, &parent_w, &jj[DIM..], 6, link_ndofs);
                }
            } else {
                self.coriolis_v[i].fill(0.0);
                self.coriolis_w[i].fill(0.0);
            }

            let shift_cross_tr = vect_to_na(link.shift23).gcross_matrix_tr();
            let dvel_cross = vect_to_na(rb.vels.angvel.gcross(link.shift23)).gcross_matrix_tr();
            let angvel_shift = angvel_cross * shift_cross_tr;
            bad |= nonfinite(shift_cross_tr.as_slice())
                | nonfinite(dvel_cross.as_slice())
                | nonfinite(angvel_shift.as_slice());
            {
                let cv = self.coriolis_v[i].as_mut_slice();
                let cw = self.coriolis_w[i].as_slice();
                let rb_j_w = &rb_j[DIM..];
                gemm3(cv, 3, 1.0, &shift_cross_tr, cw, 3, active);
                gemm3(cv, 3, 1.0, &dvel_cross, rb_j_w, 6, active);
                gemm3(cv, 3, 1.0, &angvel_shift, rb_j_w, 6, active);
            }

            /*
             * I·Coriolis·dt (upstream's `i_coriolis_dt`), active columns.
             */
            let rb_mass_dt = vect_to_na(rb_mass * dt);
            let inertia = crate::utils::mat_to_na(rb_inertia);
            let dt_inertia = inertia * dt; // only checked: the products below form dt·I_rj
            bad |= nonfinite(rb_mass_dt.as_slice()) | nonfinite(dt_inertia.as_slice());
            {
                let cv = self.coriolis_v[i].as_slice();
                let cw = self.coriolis_w[i].as_slice();
                let icd = self.i_coriolis_dt.as_mut_slice();
                for c in 0..active {
                    let (v, w) = (&cv[3 * c..3 * c + 3], &cw[3 * c..3 * c + 3]);
                    let out = &mut icd[6 * c..6 * c + 6];
                    for r in 0..3 {
                        out[r] = v[r] * rb_mass_dt[r];
                    }
                    for r in 0..3 {
                        out[3 + r] = (dt * inertia[(r, 0)]) * w[0];
                    }
                    for j in 1..3 {
                        for r in 0..3 {
                            out[3 + r] = (dt * inertia[(r, j)]) * w[j] + out[3 + r];
                        }
                    }
                }
            }

            /*
             * Jᵀ·M·J (both mass matrices) and Jᵀ·(I·Coriolis·dt), active block.
             */
            let icd = self.i_coriolis_dt.as_slice();
            let am = self.augmented_mass.as_mut_slice();
            let acc = self.acc_augmented_mass.as_mut_slice();
            let (rb_j6, icd6) = (cols6(rb_j), cols6(icd));
            for j in 0..active {
                let jj = &rb_j6[j];
                // `gemv` of the block-diagonal mass: the zero blocks' products dropped (2.).
                for r in 0..3 {
                    w0[r] = m0[(r, r)] * jj[r];
                }
                for r in 3..6 {
                    w0[r] = (m0[(r, 3)] * jj[3] + m0[(r, 4)] * jj[4]) + m0[(r, 5)] * jj[5];
                    w1[r] = (m1[(r, 3)] * jj[3] + m1[(r, 4)] * jj[4]) + m1[(r, 5)] * jj[5];
                }
                let icd_j = &icd6[j];
                let am_j = &mut am[j * n..j * n + active];
                let acc_j = &mut acc[j * n..j * n + active];
                for ((jk, am_e), acc_e) in rb_j6[..active].iter().zip(am_j).zip(acc_j) {
                    let mut lin: Real = 0.0;
                    lin += jk[0] * w0[0];
                    lin += jk[1] * w0[1];
                    lin += jk[2] * w0[2];
                    let (mut d0, mut d1) = (lin, lin);
                    for r in 3..6 {
                        d0 += jk[r] * w0[r];
                        d1 += jk[r] * w1[r];
                    }
                    let mut d2: Real = 0.0;
                    for r in 0..6 {
                        d2 += jk[r] * icd_j[r];
                    }
                    *am_e = d0 + *am_e;
                    *acc_e = d1 + *acc_e;
                    *acc_e = d2 + *acc_e;
                }
            }
        }

        bad |= nonfinite(self.augmented_mass.as_slice())
            | nonfinite(self.acc_augmented_mass.as_slice());
        bad & 0x8000_0000 == 0
    }
}
