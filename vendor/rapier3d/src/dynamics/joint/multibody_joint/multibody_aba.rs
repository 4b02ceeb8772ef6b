//! **Added for hil-sim (not in upstream rapier 0.36.1; see `vendor/rapier3d/PATCHED.md`).**
//!
//! The free accelerations of a multibody by Featherstone's articulated-body algorithm (ABA;
//! *Rigid Body Dynamics Algorithms*, 2008, §7.3), chosen per multibody with
//! [`Multibody::set_articulated_body_dynamics`]. It solves
//!
//! ```text
//! (M(q) + diag(a)) q̈ = τ − b(q, q̇)
//! ```
//!
//! for q̈ in O(links), without forming M or factorising it. The terms are those of the
//! mass-matrix route (`update_mass_matrix` + `update_acceleration`): M the joint-space mass
//! matrix of the links' effective masses and world inertias (`effective_mass`,
//! `effective_angular_inertia`); `diag(a)` rapier's diagonal, `damping·dt + armature +
//! stiffness·dt²` per dof; τ the joint springs' and dampers' generalized forces, `−k(q − q_ref)
//! − k·dt·q̇ − damping·q̇`; b the velocity-product (Coriolis, centripetal, gyroscopic) forces
//! minus the links' applied forces and torques (gravity and user forces, at each centre of
//! mass). What the ABA does not reproduce is the mass-matrix route's semi-implicit term: there
//! the Coriolis and gyroscopic forces' velocity derivative times `dt` is added to the matrix
//! that is solved (`acc_augmented_mass`); here these forces are explicit, as in rapier's own
//! fallback solve with `inv_augmented_mass`, which the mass-matrix route takes whenever the
//! semi-implicit solve adds energy. The difference is of order `dt·|q̇|` relative.
//!
//! Conventions. Spatial vectors are pairs (angular, linear): a motion `(ω, v)` with `v` the
//! velocity of the body point at the link's joint anchor (`local_frame2`'s origin, the point
//! `c2` of `forward_kinematics`), a force `(n, f)` with `n` the moment about that anchor; all
//! in world axes. Each link's quantities are about its own anchor, so that no lever arm is
//! longer than a link (f32: a common world origin would cancel large `m·|c|²` terms in the
//! wrist's articulated inertia). Moving a force from the anchor `b` of a child to the anchor
//! `a` of its parent adds `r × f` to the moment (`r = b − a`); moving a motion from `a` to `b`
//! adds `ω × r` to the linear part; an articulated inertia `[[A, B], [Bᵀ, C]]` moves to
//! `[[A + r̂B'ᵀ − B r̂, B'], [B'ᵀ, C]]` with `B' = B + r̂ C` (r̂ the cross-product matrix).
//!
//! Scope: a fixed root (a root body of type `Fixed` with a 0-dof root joint), every other joint
//! of at most one degree of freedom (a revolute or a prismatic joint, or a fixed one), no
//! kinematic dof, no dof coupling, isotropic link masses, links in topological order.
//! Anything else keeps the mass-matrix route ([`Multibody::articulated_body_applies`]).

use super::{Multibody, MultibodyLink};
use crate::dynamics::{
    LockedAxes, RigidBody, RigidBodyMassProps, RigidBodySet, RigidBodyVelocity,
};
use crate::math::{Matrix, Real, SPATIAL_DIM, Vector};
use crate::utils::AngularInertiaOps;

/// A symmetric 3×3 matrix: diagonal `(xx, yy, zz)` and off-diagonal `(yz, xz, xy)`.
#[derive(Copy, Clone, Debug, Default)]
pub(super) struct Sym3 {
    d: Vector,
    o: Vector,
}

impl Sym3 {
    #[inline(always)]
    fn mul(&self, v: Vector) -> Vector {
        let (d, o) = (self.d, self.o);
        Vector::new(
            d.x * v.x + o.z * v.y + o.y * v.z,
            o.z * v.x + d.y * v.y + o.x * v.z,
            o.y * v.x + o.x * v.y + d.z * v.z,
        )
    }

    /// `self − u wᵀ` for `u wᵀ` symmetric (w a multiple of u): its upper triangle.
    #[inline(always)]
    fn sub_outer(&self, u: Vector, w: Vector) -> Sym3 {
        Sym3 {
            d: self.d - u * w,
            o: self.o - Vector::new(u.y * w.z, u.x * w.z, u.x * w.y),
        }
    }

    #[inline(always)]
    fn add(&self, other: &Sym3) -> Sym3 {
        Sym3 {
            d: self.d + other.d,
            o: self.o + other.o,
        }
    }

    /// The symmetric part's upper triangle of a general matrix known to be symmetric.
    #[inline(always)]
    fn from_matrix(m: &Matrix) -> Sym3 {
        Sym3 {
            d: Vector::new(m.x_axis.x, m.y_axis.y, m.z_axis.z),
            o: Vector::new(m.z_axis.y, m.z_axis.x, m.y_axis.x),
        }
    }

    /// `Y + Yᵀ` of a general matrix Y.
    #[inline(always)]
    fn twice_sym(y: &Matrix) -> Sym3 {
        Sym3 {
            d: 2.0 * Vector::new(y.x_axis.x, y.y_axis.y, y.z_axis.z),
            o: Vector::new(
                y.z_axis.y + y.y_axis.z,
                y.z_axis.x + y.x_axis.z,
                y.y_axis.x + y.x_axis.y,
            ),
        }
    }

    #[inline(always)]
    fn col(&self, j: usize) -> Vector {
        let (d, o) = (self.d, self.o);
        match j {
            0 => Vector::new(d.x, o.z, o.y),
            1 => Vector::new(o.z, d.y, o.x),
            _ => Vector::new(o.y, o.x, d.z),
        }
    }
}

/// The body's world inertia about its centre of mass (kg·m²): the inverse of its effective
/// world inverse inertia, as `effective_angular_inertia` computes it (cofactors over the
/// determinant), with one division; `effective_angular_inertia` itself when a rotation is
/// locked or the matrix is singular.
#[inline(always)]
fn world_inertia(mprops: &RigidBodyMassProps) -> Sym3 {
    let m = &mprops.effective_world_inv_inertia;
    let c11 = m.m22 * m.m33 - m.m23 * m.m23;
    let c12 = m.m12 * m.m33 - m.m13 * m.m23;
    let c13 = m.m12 * m.m23 - m.m13 * m.m22;
    let det = m.m11 * c11 - m.m12 * c12 + m.m13 * c13;
    if det == 0.0 || mprops.flags.intersects(LockedAxes::ROTATION_LOCKED) {
        return Sym3::from_matrix(&mprops.effective_angular_inertia().into_matrix());
    }
    let inv = 1.0 / det;
    Sym3 {
        d: Vector::new(
            c11,
            m.m11 * m.m33 - m.m13 * m.m13,
            m.m11 * m.m22 - m.m12 * m.m12,
        ) * inv,
        o: Vector::new(m.m13 * m.m12 - m.m23 * m.m11, c13, -c12) * inv,
    }
}

/// r̂ M (r̂ x = r × x): the cross product with each column of M.
#[inline(always)]
fn cross_cols(r: Vector, m: &Matrix) -> Matrix {
    Matrix::from_cols(r.cross(m.x_axis), r.cross(m.y_axis), r.cross(m.z_axis))
}

/// r̂ S for a symmetric S.
#[inline(always)]
fn cross_cols_sym(r: Vector, s: &Sym3) -> Matrix {
    Matrix::from_cols(r.cross(s.col(0)), r.cross(s.col(1)), r.cross(s.col(2)))
}

/// One link's spatial quantities in the three passes, about its joint anchor, world axes.
#[derive(Copy, Clone, Debug, Default)]
pub(super) struct AbaLink {
    /// The joint anchor `c2` (world, m).
    anchor: Vector,
    /// The joint's motion subspace S (angular; linear at the anchor); zero for a fixed joint.
    s_w: Vector,
    s_v: Vector,
    /// The link's spatial velocity (rad/s; m/s at the anchor).
    v_w: Vector,
    v_v: Vector,
    /// The velocity-product acceleration `v × S q̇` (rad/s², m/s²).
    c_w: Vector,
    c_v: Vector,
    /// The articulated inertia `[[A, B], [Bᵀ, C]]` (kg·m², kg·m, kg), A and C symmetric.
    ia: Sym3,
    ib: Matrix,
    ic: Sym3,
    /// The articulated bias force (N·m about the anchor; N).
    p_n: Vector,
    p_f: Vector,
    /// `U = I^A S`, `D = Sᵀ U + a`, `u = τ − Sᵀ p^A` of the link's dof.
    u_n: Vector,
    u_f: Vector,
    d: Real,
    u: Real,
    /// The link's spatial acceleration (rad/s²; m/s² of the anchor, spatial).
    a_w: Vector,
    a_v: Vector,
}

impl Multibody {
    /// Selects the articulated-body algorithm (`true`) or the mass-matrix route (`false`, the
    /// default and upstream's behaviour) for this multibody's free accelerations, in
    /// [`Multibody::step_alone`] and in `PhysicsPipeline::step` alike (same inputs, same
    /// bits). The mass matrices are still built where the constraint solver needs them (the
    /// pipeline); `step_alone` skips them. Multibodies outside the algorithm's scope (see
    /// [`Multibody::articulated_body_applies`]) keep the mass-matrix route.
    pub fn set_articulated_body_dynamics(&mut self, on: bool) {
        self.articulated_body = on;
    }

    /// Whether the articulated-body algorithm was selected.
    pub fn articulated_body_dynamics(&self) -> bool {
        self.articulated_body
    }

    /// Whether the free accelerations come from the articulated-body algorithm now: it is
    /// selected, the root is fixed (a `Fixed` root body, no root dof), every other joint has at
    /// most one free (non-kinematic) dof, there is no dof coupling, every link mass is isotropic
    /// and every parent comes before its children.
    pub fn articulated_body_applies(&self, bodies: &RigidBodySet) -> bool {
        if !self.articulated_body_root_applies(bodies) {
            return false;
        }
        for (i, link) in self.links.iter().enumerate().skip(1) {
            match bodies.get(link.rigid_body) {
                Some(rb) if Self::articulated_body_link_applies(i, link, rb) => {}
                _ => return false,
            }
        }
        true
    }

    /// The conditions of [`Multibody::articulated_body_applies`] on the multibody and its root.
    #[inline]
    pub(super) fn articulated_body_root_applies(&self, bodies: &RigidBodySet) -> bool {
        if !self.articulated_body || !self.couplings.is_empty() || self.root_is_dynamic {
            return false;
        }
        let root = &self.links[0];
        root.joint.ndofs() == 0 && bodies.get(root.rigid_body).is_some_and(|rb| rb.is_fixed())
    }

    /// The conditions of [`Multibody::articulated_body_applies`] on link `i > 0` and its body.
    #[inline]
    pub(super) fn articulated_body_link_applies(
        i: usize,
        link: &MultibodyLink,
        rb: &RigidBody,
    ) -> bool {
        let m = rb.mprops.effective_mass();
        link.joint.ndofs() <= 1
            && !link.joint.kinematic
            && link.parent_internal_id < i
            && m.x == m.y
            && m.y == m.z
    }

    /// The free accelerations into `self.accelerations` by the articulated-body algorithm
    /// (module doc); the caller has checked [`Multibody::articulated_body_applies`] and run
    /// `forward_kinematics` for the current state. Sets every moving link's body velocity
    /// (centre of mass, world) from the generalized velocities on the way, as
    /// `update_velocities` does, so that `step_alone` need not run that. No allocation once
    /// the per-link buffer has the multibody's length.
    pub(super) fn update_acceleration_aba(&mut self, dt: Real, bodies: &mut RigidBodySet) {
        let n = self.links.len();
        if self.aba.len() != n {
            self.aba.resize(n, AbaLink::default());
        }
        self.accelerations.fill(0.0);

        // The fixed root: at rest, no acceleration (gravity enters as a force on each link).
        {
            let root = &self.links[0];
            self.aba[0] = AbaLink {
                anchor: root.local_to_world * root.joint.data.local_frame2.translation,
                ..AbaLink::default()
            };
        }

        // Pass 1, root to tips: velocities, velocity-product accelerations, rigid-body
        // inertias and bias forces.
        for i in 1..n {
            let link = &self.links[i];
            let parent = &self.links[link.parent_internal_id];
            let rb = bodies.index_mut_internal(link.rigid_body);
            let (done, rest) = self.aba.split_at_mut(i);
            let lp = &done[link.parent_internal_id];
            let l = &mut rest[0];

            l.anchor = link.local_to_world * link.joint.data.local_frame2.translation;
            let r = l.anchor - lp.anchor;
            let v_w = lp.v_w;
            let v_v = lp.v_v + lp.v_w.cross(r);

            // S as `MultibodyJoint::jacobian` gives it for one free axis: a translation along,
            // or a rotation about, an axis of the joint frame (local_frame1 in the parent).
            let (mut s_w, mut s_v, mut qd) = (Vector::ZERO, Vector::ZERO, 0.0);
            let free = !link.joint.data.locked_axes.bits() & ((1 << SPATIAL_DIM) - 1);
            if free != 0 {
                let axis = free.trailing_zeros() as usize;
                let rot = parent.local_to_world.rotation * link.joint.data.local_frame1.rotation;
                if axis < 3 {
                    s_v = rot * Vector::AXES[axis];
                } else {
                    s_w = rot * Vector::AXES[axis - 3];
                }
                qd = self.velocities[link.assembly_id];
            }
            let (m_w, m_v) = (s_w * qd, s_v * qd);
            l.s_w = s_w;
            l.s_v = s_v;
            l.c_w = v_w.cross(m_w);
            l.c_v = v_w.cross(m_v) + v_v.cross(m_w);
            l.v_w = v_w + m_w;
            l.v_v = v_v + m_v;
            let rc = link.shift23;

            // The rigid-body inertia about the anchor, the centre of mass at `shift23 = rc`:
            // A = I_c + m (|rc|² 1 − rc rcᵀ), B = m r̂c, C = m 1.
            let mass = rb.mprops.effective_mass().x;
            let ic = world_inertia(&rb.mprops);
            let mrc = rc * mass;
            let rr = rc.dot(mrc);
            l.ia = Sym3 {
                d: ic.d + Vector::splat(rr) - rc * mrc,
                o: ic.o - Vector::new(rc.y * mrc.z, rc.x * mrc.z, rc.x * mrc.y),
            };
            l.ib = Matrix::from_cols(
                Vector::new(0.0, mrc.z, -mrc.y),
                Vector::new(-mrc.z, 0.0, mrc.x),
                Vector::new(mrc.y, -mrc.x, 0.0),
            );
            l.ic = Sym3 {
                d: Vector::splat(mass),
                o: Vector::ZERO,
            };

            // Bias force v ×* (I v) minus the applied force (at the centre of mass) and torque:
            // I v = (A ω + m rc × v, m (v − rc × ω)).
            let h_n = l.ia.mul(l.v_w) + mrc.cross(l.v_v);
            let h_f = l.v_v * mass - mrc.cross(l.v_w);
            let f = rb.forces.force;
            let moment = rb.forces.torque + rc.cross(f);
            l.p_n = l.v_w.cross(h_n) + l.v_v.cross(h_f) - moment;
            l.p_f = l.v_w.cross(h_f) - f;

            // The body's velocity, as `update_velocities` would set it (the centre of mass's).
            let vels = RigidBodyVelocity {
                linvel: l.v_v + l.v_w.cross(rc),
                angvel: l.v_w,
            };
            rb.vels = vels;
        }

        // Pass 2, tips to root: articulated inertias and bias forces.
        for i in (1..n).rev() {
            let link = &self.links[i];
            let pid = link.parent_internal_id;
            let (diag, tau) = self.dof_diagonal_and_force(i, dt);
            let (done, rest) = self.aba.split_at_mut(i);
            let l = &mut rest[0];

            if link.joint.ndofs() == 1 {
                let dof = link.assembly_id;
                let ibt = l.ib.transpose();
                let tau = tau - self.damping[dof] * self.velocities[dof];
                if l.s_v == Vector::ZERO {
                    // A revolute joint: S = (s_w, 0).
                    l.u_n = l.ia.mul(l.s_w);
                    l.u_f = ibt * l.s_w;
                    l.d = l.s_w.dot(l.u_n) + diag;
                    l.u = tau - l.s_w.dot(l.p_n);
                } else {
                    l.u_n = l.ia.mul(l.s_w) + l.ib * l.s_v;
                    l.u_f = ibt * l.s_w + l.ic.mul(l.s_v);
                    l.d = l.s_w.dot(l.u_n) + l.s_v.dot(l.u_f) + diag;
                    l.u = tau - (l.s_w.dot(l.p_n) + l.s_v.dot(l.p_f));
                }
                if pid != 0 {
                    // I^a = I^A − U Uᵀ / D; p^a = p^A + I^a c + U u / D.
                    let inv_d = 1.0 / l.d;
                    let (un_d, uf_d) = (l.u_n * inv_d, l.u_f * inv_d);
                    let ia = l.ia.sub_outer(l.u_n, un_d);
                    let ib = l.ib - Matrix::from_cols(un_d * l.u_f.x, un_d * l.u_f.y, un_d * l.u_f.z);
                    let ic = l.ic.sub_outer(l.u_f, uf_d);
                    let p_n = l.p_n + ia.mul(l.c_w) + ib * l.c_v + un_d * l.u;
                    let p_f = l.p_f + ib.transpose() * l.c_w + ic.mul(l.c_v) + uf_d * l.u;
                    Self::aba_add_to_parent(&mut done[pid], l.anchor, &ia, &ib, &ic, p_n, p_f);
                }
            } else if pid != 0 {
                // A fixed joint: no dof, no velocity product (c = 0): I^a = I^A, p^a = p^A.
                let (ia, ib, ic) = (l.ia, l.ib, l.ic);
                Self::aba_add_to_parent(&mut done[pid], l.anchor, &ia, &ib, &ic, l.p_n, l.p_f);
            }
        }

        // Pass 3, root to tips: accelerations.
        for i in 1..n {
            let link = &self.links[i];
            let (done, rest) = self.aba.split_at_mut(i);
            let lp = &done[link.parent_internal_id];
            let l = &mut rest[0];
            let r = l.anchor - lp.anchor;
            l.a_w = lp.a_w + l.c_w;
            l.a_v = lp.a_v + lp.a_w.cross(r) + l.c_v;
            if link.joint.ndofs() == 1 {
                let qdd = (l.u - (l.u_n.dot(l.a_w) + l.u_f.dot(l.a_v))) / l.d;
                l.a_w += l.s_w * qdd;
                l.a_v += l.s_v * qdd;
                self.accelerations[link.assembly_id] = qdd;
            }
        }
    }

    /// The dof of 1-dof link `i`: rapier's diagonal term `damping·dt + armature +
    /// stiffness·dt²` and the spring's generalized force `−k(q − q_ref) − k·dt·q̇` (the
    /// damper's `−damping·q̇` is added by the caller), as `update_mass_matrix` and
    /// `update_acceleration` form them.
    #[inline]
    fn dof_diagonal_and_force(&self, i: usize, dt: Real) -> (Real, Real) {
        let link = &self.links[i];
        if link.joint.ndofs() != 1 {
            return (0.0, 0.0);
        }
        let dof = link.assembly_id;
        let mut diag = self.damping[dof] * dt + self.armature[dof];
        let mut force = 0.0;
        let free = !link.joint.data.locked_axes.bits() & ((1 << SPATIAL_DIM) - 1);
        let axis = free.trailing_zeros() as usize;
        let k = link.joint.spring_stiffness[axis];
        if k != 0.0 {
            let q = link.joint.coords[axis];
            let rest = link.joint.spring_ref[axis];
            force = -k * (q - rest) - k * dt * self.velocities[dof];
            diag += k * (dt * dt);
        }
        (diag, force)
    }

    /// Adds a child's articulated inertia and bias force, about the child's anchor `b`, to its
    /// parent's, about the parent's anchor (module doc: the shift by `r = b − a`):
    /// B' = B + r̂ C, A' = A + Y + Yᵀ + r̂ (r̂ C)ᵀ with Y = r̂ Bᵀ, n' = n + r × f.
    #[inline(always)]
    fn aba_add_to_parent(
        parent: &mut AbaLink,
        b: Vector,
        ia: &Sym3,
        ib: &Matrix,
        ic: &Sym3,
        p_n: Vector,
        p_f: Vector,
    ) {
        let r = b - parent.anchor;
        let w = cross_cols_sym(r, ic);
        let y = cross_cols(r, &ib.transpose());
        let rcr = cross_cols(r, &w.transpose());
        parent.ia = parent
            .ia
            .add(ia)
            .add(&Sym3::twice_sym(&y))
            .add(&Sym3::from_matrix(&rcr));
        parent.ib += *ib + w;
        parent.ic = parent.ic.add(ic);
        parent.p_n += p_n + r.cross(p_f);
        parent.p_f += p_f;
    }
}
