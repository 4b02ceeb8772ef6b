//! The simulator's rigid-body dynamics against an independent f64 computation written here from
//! the URDF parameters: forward kinematics, recursive Newton–Euler inverse dynamics, the mass
//! matrix, forward dynamics, the potential energy and its gradient.
//!
//! The reference model parses the bundled URDF itself and folds the wrist lock rotations into
//! the wrist joint origins itself (it does not use `ArmModel::locked`, whose lock is checked
//! against this one in `state_layout_matches_forward_kinematics`). Everything is f64; rapier
//! runs in f32, so tolerances below are set from what f32 physics can reach, never widened to
//! make a test pass.

use hil_sim::model::{urdf_pose_to_isometry, BUNDLED_URDF};
use hil_sim::Ur5Sim;
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, Unit, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use ur5_shared::config::SimConfig;
use ur5_shared::layout::ACTIVE_JOINTS;

/// Standard gravity (m/s²) along −z of the base frame (the value the task specifies).
const G: f64 = 9.81;

/// Independent rigid-body model of the serial arm with locked wrists.
pub(crate) mod reference {
    use super::*;

    /// One link of the serial chain, with the joint that connects it to the previous link.
    #[derive(Clone, Debug)]
    pub struct Body {
        pub name: String,
        /// Joint origin in the parent link frame (identity for the root). For a locked wrist
        /// joint the lock rotation is folded in.
        pub origin: Isometry3<f64>,
        /// Joint axis in this link's frame (unit).
        pub axis: Vector3<f64>,
        /// Index into q of an active joint; `None` for the root and locked joints.
        pub dof: Option<usize>,
        pub mass: f64,
        /// Centre of mass in the link frame.
        pub com: Vector3<f64>,
        /// Inertia tensor about the COM, axes of the link frame.
        pub inertia: Matrix3<f64>,
    }

    /// The arm: bodies in chain order from the fixed root.
    #[derive(Clone, Debug)]
    pub struct Arm {
        pub bodies: Vec<Body>,
        /// Names of the joints of `bodies[1..]` (as in the URDF, chain order).
        pub joint_names: Vec<String>,
    }

    /// URDF fixed-axis roll-pitch-yaw: R = Rz(yaw) Ry(pitch) Rx(roll), written out here.
    pub fn rpy(r: f64, p: f64, y: f64) -> Matrix3<f64> {
        let (sr, cr) = r.sin_cos();
        let (sp, cp) = p.sin_cos();
        let (sy, cy) = y.sin_cos();
        let rx = Matrix3::new(1.0, 0.0, 0.0, 0.0, cr, -sr, 0.0, sr, cr);
        let ry = Matrix3::new(cp, 0.0, sp, 0.0, 1.0, 0.0, -sp, 0.0, cp);
        let rz = Matrix3::new(cy, -sy, 0.0, sy, cy, 0.0, 0.0, 0.0, 1.0);
        rz * ry * rx
    }

    pub fn pose(p: &urdf_rs::Pose) -> Isometry3<f64> {
        let [r, pi, y] = p.rpy.0;
        Isometry3::from_parts(
            Translation3::from(Vector3::from(p.xyz.0)),
            UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(rpy(r, pi, y))),
        )
    }

    impl Arm {
        /// The bundled UR5 with the wrist joints locked at `wrist_q` (chain order).
        pub fn bundled(wrist_q: [f64; 3]) -> Self {
            Self::of(BUNDLED_URDF, wrist_q)
        }

        /// The arm of URDF `text` with the wrist joints locked at `wrist_q` (chain order).
        pub fn of(text: &str, wrist_q: [f64; 3]) -> Self {
            let robot = urdf_rs::read_from_string(text).expect("the URDF parses");
            let root = robot
                .links
                .iter()
                .find(|l| !robot.joints.iter().any(|j| j.child.link == l.name))
                .expect("a root link");
            let link_body = |l: &urdf_rs::Link| {
                let i = &l.inertial;
                assert_eq!(
                    i.origin.rpy.0, [0.0; 3],
                    "link {}: the reference assumes inertial rpy = 0",
                    l.name
                );
                let t = &i.inertia;
                Body {
                    name: l.name.clone(),
                    origin: Isometry3::identity(),
                    axis: Vector3::z(),
                    dof: None,
                    mass: i.mass.value,
                    com: Vector3::from(i.origin.xyz.0),
                    inertia: Matrix3::new(
                        t.ixx, t.ixy, t.ixz, t.ixy, t.iyy, t.iyz, t.ixz, t.iyz, t.izz,
                    ),
                }
            };
            let mut bodies = vec![link_body(root)];
            let mut joint_names = Vec::new();
            let mut n_wrist = 0;
            loop {
                let parent = &bodies.last().unwrap().name;
                let children: Vec<_> = robot
                    .joints
                    .iter()
                    .filter(|j| j.parent.link == *parent)
                    .collect();
                if children.is_empty() {
                    break;
                }
                assert_eq!(
                    children.len(),
                    1,
                    "the reference handles serial chains only"
                );
                let j = children[0];
                let link = robot
                    .links
                    .iter()
                    .find(|l| l.name == j.child.link)
                    .expect("child link");
                let mut b = link_body(link);
                let axis = Vector3::from(j.axis.xyz.0).normalize();
                b.axis = axis;
                b.origin = pose(&j.origin);
                if let Some(k) = ACTIVE_JOINTS.iter().position(|n| *n == j.name) {
                    assert_eq!(j.joint_type, urdf_rs::JointType::Revolute);
                    b.dof = Some(k);
                } else if j.joint_type != urdf_rs::JointType::Fixed {
                    // Locked: the child frame sits at origin · Rot(axis, q_lock).
                    b.origin *= UnitQuaternion::from_axis_angle(
                        &Unit::new_normalize(axis),
                        wrist_q[n_wrist],
                    );
                    n_wrist += 1;
                }
                joint_names.push(j.name.clone());
                bodies.push(b);
            }
            assert_eq!(n_wrist, 3, "three wrist joints locked");
            let dofs: Vec<_> = bodies.iter().filter_map(|b| b.dof).collect();
            assert_eq!(dofs, vec![0, 1, 2], "active joints in chain order");
            Self {
                bodies,
                joint_names,
            }
        }

        pub fn index(&self, link: &str) -> usize {
            self.bodies
                .iter()
                .position(|b| b.name == link)
                .expect("link")
        }

        /// World pose of every link frame.
        pub fn fk(&self, q: &[f64; 3]) -> Vec<Isometry3<f64>> {
            let mut out: Vec<Isometry3<f64>> = Vec::with_capacity(self.bodies.len());
            for (i, b) in self.bodies.iter().enumerate() {
                let parent = if i == 0 {
                    Isometry3::identity()
                } else {
                    out[i - 1]
                };
                let mut t = parent * b.origin;
                if let Some(k) = b.dof {
                    t *= UnitQuaternion::from_axis_angle(&Unit::new_unchecked(b.axis), q[k]);
                }
                out.push(t);
            }
            out
        }

        /// World position of every link's centre of mass.
        pub fn coms(&self, q: &[f64; 3]) -> Vec<Vector3<f64>> {
            self.fk(q)
                .iter()
                .zip(&self.bodies)
                .map(|(t, b)| (t * nalgebra::Point3::from(b.com)).coords)
                .collect()
        }

        /// Potential energy Σ m g z_com over the moving links (J); the fixed root is left out.
        pub fn potential(&self, q: &[f64; 3]) -> f64 {
            let c = self.coms(q);
            self.bodies
                .iter()
                .zip(&c)
                .skip(1)
                .map(|(b, p)| b.mass * G * p.z)
                .sum()
        }

        /// ∂V/∂q by fourth-order central differences (h = 1e-3 rad: truncation ~1e-12,
        /// round-off ~1e-11 N·m).
        pub fn gravity_fd(&self, q: &[f64; 3]) -> [f64; 3] {
            let h = 1e-3;
            let v = |k: usize, s: f64| {
                let mut qq = *q;
                qq[k] += s * h;
                self.potential(&qq)
            };
            [0, 1, 2].map(|k| {
                (-v(k, 2.0) + 8.0 * v(k, 1.0) - 8.0 * v(k, -1.0) + v(k, -2.0)) / (12.0 * h)
            })
        }

        /// Recursive Newton–Euler inverse dynamics in the world frame: the joint torques that
        /// give accelerations `qdd` at (`q`, `qd`), with gravity (0, 0, −g·gravity).
        pub fn rnea(&self, q: &[f64; 3], qd: &[f64; 3], qdd: &[f64; 3], gravity: f64) -> [f64; 3] {
            let n = self.bodies.len();
            let poses = self.fk(q);
            let z = Vector3::zeros();
            let (mut w, mut wd, mut a) = (vec![z; n], vec![z; n], vec![z; n]);
            // Gravity as an upward acceleration of the fixed base.
            a[0] = Vector3::new(0.0, 0.0, G * gravity);
            let (mut f_in, mut n_in, mut rc) = (vec![z; n], vec![z; n], vec![z; n]);
            for i in 1..n {
                let b = &self.bodies[i];
                let d = poses[i].translation.vector - poses[i - 1].translation.vector;
                // The joint sits at this link's origin, a point fixed in the parent link.
                a[i] = a[i - 1] + wd[i - 1].cross(&d) + w[i - 1].cross(&w[i - 1].cross(&d));
                (w[i], wd[i]) = match b.dof {
                    Some(k) => {
                        let zi = poses[i].rotation * b.axis;
                        (
                            w[i - 1] + zi * qd[k],
                            wd[i - 1] + zi * qdd[k] + w[i - 1].cross(&zi) * qd[k],
                        )
                    }
                    None => (w[i - 1], wd[i - 1]),
                };
                let r = poses[i].rotation.to_rotation_matrix().into_inner();
                rc[i] = r * b.com;
                let ac = a[i] + wd[i].cross(&rc[i]) + w[i].cross(&w[i].cross(&rc[i]));
                let iw = r * b.inertia * r.transpose();
                f_in[i] = b.mass * ac;
                n_in[i] = iw * wd[i] + w[i].cross(&(iw * w[i]));
            }
            let mut tau = [0.0; 3];
            let (mut f_child, mut n_child) = (z, z);
            for i in (1..n).rev() {
                let b = &self.bodies[i];
                // Force and moment (about this link's origin) the parent exerts on link i.
                let d_child = if i + 1 < n {
                    poses[i + 1].translation.vector - poses[i].translation.vector
                } else {
                    z
                };
                let f = f_in[i] + f_child;
                let m = n_in[i] + rc[i].cross(&f_in[i]) + n_child + d_child.cross(&f_child);
                if let Some(k) = b.dof {
                    tau[k] = (poses[i].rotation * b.axis).dot(&m);
                }
                (f_child, n_child) = (f, m);
            }
            tau
        }

        /// Joint-space mass matrix: column k = RNEA(q, 0, e_k) without gravity.
        pub fn mass_matrix(&self, q: &[f64; 3]) -> Matrix3<f64> {
            let mut m = Matrix3::zeros();
            for k in 0..3 {
                let mut e = [0.0; 3];
                e[k] = 1.0;
                m.set_column(k, &Vector3::from(self.rnea(q, &[0.0; 3], &e, 0.0)));
            }
            m
        }

        /// Forward dynamics: q̈ = M⁻¹ (τ − h(q, q̇)), h = RNEA(q, q̇, 0) with gravity.
        pub fn forward(&self, q: &[f64; 3], qd: &[f64; 3], tau: &[f64; 3]) -> [f64; 3] {
            let h = Vector3::from(self.rnea(q, qd, &[0.0; 3], 1.0));
            let m = self.mass_matrix(q);
            let qdd = m
                .cholesky()
                .expect("M(q) positive definite")
                .solve(&(Vector3::from(*tau) - h));
            [qdd.x, qdd.y, qdd.z]
        }

        /// Total energy ½ q̇ᵀ M q̇ + V and the kinetic part.
        pub fn energy(&self, q: &[f64; 3], qd: &[f64; 3]) -> (f64, f64) {
            let v = Vector3::from(*qd);
            let ke = 0.5 * v.dot(&(self.mass_matrix(q) * v));
            (ke + self.potential(q), ke)
        }
    }
}

pub(crate) use reference::Arm;

fn default_wrist() -> [f64; 3] {
    SimConfig::default().wrist_q
}

/// A random joint configuration inside the URDF limits of the active joints.
pub(crate) fn random_q(rng: &mut ChaCha8Rng, sim: &Ur5Sim) -> [f64; 3] {
    let a = &sim.model().active;
    [0, 1, 2].map(|j| rng.random_range(a[j].lower..a[j].upper))
}

fn norm3(v: [f64; 3]) -> f64 {
    Vector3::from(v).norm()
}

fn sub3(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// The reference itself: internal consistency (gravity from RNEA equals the gradient of V, M is
/// symmetric positive definite, RNEA ∘ forward dynamics is the identity, ½ q̇ᵀMq̇ equals the sum
/// of the links' kinetic energies from FK differences). Guards the tests below against a wrong
/// reference.
#[test]
fn reference_dynamics_is_self_consistent() {
    let arm = Arm::bundled(default_wrist());
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    for _ in 0..20 {
        let q = [0, 1, 2].map(|_| rng.random_range(-3.0..3.0));
        let qd = [0, 1, 2].map(|_| rng.random_range(-1.5..1.5));
        let tau = [0, 1, 2].map(|_| rng.random_range(-40.0..40.0));

        let g_rnea = arm.rnea(&q, &[0.0; 3], &[0.0; 3], 1.0);
        let g_fd = arm.gravity_fd(&q);
        assert!(
            norm3(sub3(g_rnea, g_fd)) < 1e-8,
            "RNEA gravity {g_rnea:?} vs ∂V/∂q {g_fd:?}"
        );

        let m = arm.mass_matrix(&q);
        assert!(
            (m - m.transpose()).abs().max() < 1e-12,
            "M not symmetric: {m}"
        );
        assert!(
            m.symmetric_eigenvalues().min() > 0.0,
            "M not positive definite: {m}"
        );

        let qdd = arm.forward(&q, &qd, &tau);
        let back = arm.rnea(&q, &qd, &qdd, 1.0);
        assert!(
            norm3(sub3(back, tau)) < 1e-9,
            "RNEA(FD(τ)) = {back:?} ≠ τ = {tau:?}"
        );

        // Kinetic energy from link velocities by central differences of FK along q̇.
        let h = 1e-6;
        let plus = arm.fk(&[0, 1, 2].map(|k| q[k] + h * qd[k]));
        let minus = arm.fk(&[0, 1, 2].map(|k| q[k] - h * qd[k]));
        let mut ke = 0.0;
        for (i, b) in arm.bodies.iter().enumerate().skip(1) {
            let cp = plus[i] * nalgebra::Point3::from(b.com);
            let cm = minus[i] * nalgebra::Point3::from(b.com);
            let v = (cp - cm) / (2.0 * h);
            let dr = plus[i].rotation * minus[i].rotation.inverse();
            let w = dr.scaled_axis() / (2.0 * h);
            let r = plus[i]
                .rotation
                .slerp(&minus[i].rotation, 0.5)
                .to_rotation_matrix()
                .into_inner();
            let iw = r * b.inertia * r.transpose();
            ke += 0.5 * b.mass * v.norm_squared() + 0.5 * w.dot(&(iw * w));
        }
        let (_, ke_m) = arm.energy(&q, &qd);
        assert!(
            (ke - ke_m).abs() < 1e-7 * ke_m.max(1.0),
            "½q̇ᵀMq̇ = {ke_m} vs Σ link KE = {ke}"
        );
    }
}

/// Test 1: the simulator's joint accelerations at 0.1 ms agree with M⁻¹(τ − h) within 1 %.
///
/// Error measure: max_j |q̈_sim,j − q̈_ref,j| / max_j |q̈_ref,j| (one scale per state, so a joint
/// whose acceleration happens to be near zero is judged against the state's acceleration scale
/// rather than against its own tiny value). Expected from UR5.md: ≈ 2.5e-4 at 0.1 ms (first
/// order in the step).
#[test]
fn joint_accelerations_match_newton_euler() {
    let cfg = SimConfig {
        physics_dt: 1e-4,
        substeps: 1,
        ..Default::default()
    };
    let arm = Arm::bundled(cfg.wrist_q);
    let mut sim = Ur5Sim::new(cfg, 1e-4).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(2024);
    let mut worst = 0.0f64;
    let mut worst_state = String::new();
    for _ in 0..20 {
        let q = random_q(&mut rng, &sim);
        let qd = [0, 1, 2].map(|_| rng.random_range(-1.5..1.5));
        let tau = [0, 1, 2].map(|_| rng.random_range(-40.0..40.0));
        // Compare at the state the f32 multibody actually holds.
        sim.set_joint_state(q, qd);
        let (q, qd) = sim.joint_state();
        let a_sim = sim.joint_acceleration(q, qd, tau);
        let a_ref = arm.forward(&q, &qd, &tau);
        let scale = a_ref.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let err = sub3(a_sim, a_ref)
            .iter()
            .fold(0.0f64, |m, v| m.max(v.abs()))
            / scale;
        if err > worst {
            worst = err;
            worst_state = format!("q {q:?} qd {qd:?} tau {tau:?}: sim {a_sim:?} ref {a_ref:?}");
        }
    }
    eprintln!("joint acceleration: max relative error {worst:.3e} ({worst_state})");
    assert!(
        worst < 0.01,
        "joint accelerations off by {worst:.3e} (> 1 %) relative: {worst_state}"
    );
}

/// Worst |gravity_torque() − ∂V/∂q| over `poses`, with a description of where.
fn feed_forward_error(sim: &mut Ur5Sim, arm: &Arm, poses: &[[f64; 3]]) -> (f64, [f64; 3], String) {
    let mut worst = (0.0f64, [0.0; 3], String::new());
    for &q in poses {
        sim.set_joint_state(q, [0.0; 3]);
        let (q, _) = sim.joint_state();
        let (g_sim, g_ref) = (sim.gravity_torque(), arm.gravity_fd(&q));
        let e = norm3(sub3(g_sim, g_ref));
        if e > worst.0 {
            worst = (
                e,
                q,
                format!("at q {q:?}: gravity_torque() {g_sim:?}, ∂V/∂q {g_ref:?}"),
            );
        }
    }
    worst
}

fn feed_forward_poses(cfg: &SimConfig) -> Vec<[f64; 3]> {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let sim = Ur5Sim::new(cfg.clone(), cfg.physics_dt).unwrap();
    (0..30).map(|_| random_q(&mut rng, &sim)).collect()
}

// Tolerance of both feed-forward tests, 1e-4 N·m: f32 Jacobians and COMs carry ~1e-7 relative
// rounding on terms up to ~50 N·m (the largest gravity torque, at full reach), i.e. ~1e-5 N·m;
// 1e-4 N·m is ≈ 2e-6 of the largest gravity torque.

/// Test 2a: the servo's gravity feed-forward `gravity_torque()` equals ∂V/∂q of the
/// independent potential energy once the physics has stepped.
#[test]
fn gravity_feed_forward_matches_potential_gradient() {
    let cfg = SimConfig {
        physics_dt: 1e-3,
        substeps: 1,
        ..Default::default()
    };
    let arm = Arm::bundled(cfg.wrist_q);
    let mut sim = Ur5Sim::new(cfg.clone(), 1e-3).unwrap();
    sim.step_torque_raw([0.0; 3]);
    let (e, _, at) = feed_forward_error(&mut sim, &arm, &feed_forward_poses(&cfg));
    eprintln!("gravity_torque() vs ∂V/∂q after a step: max error {e:.3e} N·m ({at})");
    assert!(
        e < 1e-4,
        "gravity feed-forward differs from ∂V/∂q by {e:.3e} N·m {at}"
    );
}

/// Test 2a': the same on a freshly built simulator that has not stepped yet: the state the
/// servo's first physics step sees after `Ur5Sim::new` + `reset`, and what any caller of
/// `gravity_torque()` gets before the first step.
#[test]
fn gravity_feed_forward_is_right_before_the_first_step() {
    let cfg = SimConfig {
        physics_dt: 1e-3,
        substeps: 1,
        ..Default::default()
    };
    let arm = Arm::bundled(cfg.wrist_q);
    let mut sim = Ur5Sim::new(cfg.clone(), 1e-3).unwrap();
    let (e, q, at) = feed_forward_error(&mut sim, &arm, &feed_forward_poses(&cfg));
    // Diagnosis: the same gradient with every link's COM moved to its link frame origin.
    let mut origins = arm.clone();
    for b in &mut origins.bodies {
        b.com = Vector3::zeros();
    }
    let g_origins = origins.gravity_fd(&q);
    eprintln!(
        "gravity_torque() vs ∂V/∂q on a fresh sim: max error {e:.3e} N·m ({at}); ∂V/∂q with COMs \
         at the link origins there: {g_origins:?}"
    );
    assert!(
        e < 1e-4,
        "on a never-stepped simulator the gravity feed-forward differs from ∂V/∂q by {e:.3e} N·m \
         {at}; ∂V/∂q with every COM at its link origin would be {g_origins:?}"
    );
}

/// Test 2b: torques from the gradient of the independent potential energy, recomputed at the
/// current q every 1 ms step, hold the arm within 1e-3 rad for 10 s from several poses.
///
/// The bound is near what f32 physics allows: rapier's gravity model differs from the f64
/// gradient by up to ~4e-5 N·m (f32 rounding, see test 2a); against ~3 kg·m² at full reach a
/// constant bias ε drifts ½ (ε/M) t² ≈ 7e-4 rad in 10 s. Measured: up to ≈ 6e-4 rad.
#[test]
fn gravity_gradient_holds_the_arm() {
    let cfg = SimConfig {
        physics_dt: 1e-3,
        substeps: 1,
        ..Default::default()
    };
    let arm = Arm::bundled(cfg.wrist_q);
    let mut sim = Ur5Sim::new(cfg, 1e-3).unwrap();

    let starts = [
        [0.0, -2.0, 2.4],
        [0.0, 0.0, 0.0],
        [0.7, -1.0, 1.2],
        [-1.3, -0.4, -1.7],
        [2.0, -2.6, 0.5],
    ];
    let mut worst = 0.0f64;
    for q0 in starts {
        sim.set_joint_state(q0, [0.0; 3]);
        let (q0, _) = sim.joint_state();
        let mut drift = 0.0f64;
        for _ in 0..10_000 {
            let (q, _) = sim.joint_state();
            drift = drift.max(sub3(q, q0).iter().fold(0.0f64, |m, v| m.max(v.abs())));
            sim.step_torque_raw(arm.gravity_fd(&q));
        }
        let (q, _) = sim.joint_state();
        drift = drift.max(sub3(q, q0).iter().fold(0.0f64, |m, v| m.max(v.abs())));
        eprintln!("gravity hold from {q0:?}: max |q − q0| over 10 s = {drift:.3e} rad");
        worst = worst.max(drift);
    }
    assert!(
        worst < 1e-3,
        "arm drifted {worst:.3e} rad (≥ 1e-3) under ∂V/∂q torques"
    );
}

/// Test 3: a passive swing at 0.1 ms conserves E = ½ q̇ᵀMq̇ + V to better than 1 % of the peak
/// kinetic energy per second (UR5.md: rapier loses ≈ 0.2 %/s at 0.1 ms).
///
/// Drift rate: the least-squares slope of E(t) over the whole run (the symplectic integrator's
/// in-period energy oscillation averages out); the end-to-end change (E(T) − E(0))/T is held to
/// the same bound.
#[test]
fn passive_swing_conserves_energy() {
    let dt = 1e-4;
    let cfg = SimConfig {
        physics_dt: dt,
        substeps: 1,
        ..Default::default()
    };
    let arm = Arm::bundled(cfg.wrist_q);
    let mut sim = Ur5Sim::new(cfg, dt).unwrap();
    let steps = 25_000; // 2.5 s
    let mut worst = 0.0f64;
    let limits = sim.model().active.clone();
    // Swings about the hanging pose (shoulder lift +π/2) plus one fall from full horizontal
    // reach. Each must stay clear of the URDF position limits, which rapier enforces as
    // inelastic stops: a limit hit removes energy by design and is not integrator drift.
    for q0 in [
        [0.3, 0.9, 0.8],
        [-0.6, 2.3, -1.0],
        [1.0, 1.2, 1.6],
        [0.0, 0.0, 0.0],
    ] {
        sim.set_joint_state(q0, [0.0; 3]);
        let (mut sum_t, mut sum_e, mut sum_tt, mut sum_te) = (0.0, 0.0, 0.0, 0.0);
        let mut ke_peak = 0.0f64;
        let (mut e0, mut e_end) = (0.0, 0.0);
        let mut margin = f64::INFINITY;
        for s in 0..=steps {
            let (q, qd) = sim.joint_state();
            for (j, l) in limits.iter().enumerate() {
                margin = margin.min(q[j] - l.lower).min(l.upper - q[j]);
            }
            let (e, ke) = arm.energy(&q, &qd);
            let t = s as f64 * dt;
            if s == 0 {
                e0 = e;
            }
            e_end = e;
            ke_peak = ke_peak.max(ke);
            sum_t += t;
            sum_e += e;
            sum_tt += t * t;
            sum_te += t * e;
            if s < steps {
                sim.step_torque_raw([0.0; 3]);
            }
        }
        let n = (steps + 1) as f64;
        let slope = (n * sum_te - sum_t * sum_e) / (n * sum_tt - sum_t * sum_t);
        let t_end = steps as f64 * dt;
        let end_rate = (e_end - e0) / t_end;
        let rel = slope.abs().max(end_rate.abs()) / ke_peak;
        eprintln!(
            "passive swing from {q0:?}: peak KE {ke_peak:.3} J, dE/dt fit {slope:.4e} J/s, \
             end-to-end {end_rate:.4e} J/s → {:.3} % of peak KE per s; closest to a limit {margin:.3} rad",
            rel * 100.0
        );
        assert!(
            margin > 0.05,
            "test set-up: the swing from {q0:?} comes within {margin:.3} rad of a joint limit \
             (an inelastic stop), so its energy loss is not integrator drift; pick another pose"
        );
        assert!(
            ke_peak > 1.0,
            "the arm barely moved from {q0:?} (peak KE {ke_peak} J)"
        );
        worst = worst.max(rel);
    }
    assert!(
        worst < 0.01,
        "energy drift {:.3} % of peak KE per second (≥ 1 %)",
        worst * 100.0
    );
}

/// Test 4: the observation's end-effector position is the FK of wrist_3_link's origin (plus
/// the configured offset, zero by default) and its velocity is J(q) q̇.
///
/// ee_pos: ≤ 1e-6 m, FK evaluated at the angles the f32 multibody holds (`obs.q`).
/// ee_vel: J(q)q̇ by central differences of FK along q̇ (h = 1e-6, error ~1e-10 m/s); bound
/// |Δv| ≤ 1e-4 · max(|v_ref|, 1 m/s), i.e. 1e-4 m/s absolute for slow motion and 1e-4 relative
/// for fast motion (f32 Jacobians carry ~1e-7 relative error).
#[test]
fn state_layout_matches_forward_kinematics() {
    let mut rng = ChaCha8Rng::seed_from_u64(99);
    let mut worst_pos = [0.0f64; 2];
    let mut worst_pos_requested = 0.0f64;
    let mut worst_vel = [(0.0f64, String::new()), (0.0f64, String::new())];
    for wrist_q in [default_wrist(), [0.3, -0.7, 1.1]] {
        let cfg = SimConfig {
            wrist_q,
            ..SimConfig::default()
        };
        let arm = Arm::bundled(wrist_q);
        let mut sim = Ur5Sim::new(cfg, 0.1).unwrap();

        // The simulator's locked URDF folds the same lock rotations into the joint origins.
        let locked = &sim.model().locked;
        for (b, name) in arm.bodies.iter().skip(1).zip(&arm.joint_names) {
            let j = locked.joints.iter().find(|j| j.name == *name).unwrap();
            let mine = reference::pose(&j.origin);
            assert!(
                (urdf_pose_to_isometry(&j.origin).to_matrix() - mine.to_matrix())
                    .abs()
                    .max()
                    < 1e-12
            );
            if b.dof.is_none() {
                let d = (b.origin.to_matrix() - mine.to_matrix()).abs().max();
                assert!(
                    d < 1e-12,
                    "locked origin of {name} differs from origin·Rot(axis, q_lock) by {d:e}"
                );
            }
        }

        let ee = arm.index("wrist_3_link");
        let fk_ee = |q: &[f64; 3]| arm.fk(q)[ee].translation.vector;
        for i in 0..25 {
            // The first 5 samples on the never-stepped simulator, the rest after one step
            // (rapier fills in the bodies' mass properties at the first step).
            let phase = usize::from(i >= 5);
            if i == 5 {
                sim.step_torque_raw([0.0; 3]);
            }
            let q = random_q(&mut rng, &sim);
            let qd = [0, 1, 2].map(|_| rng.random_range(-1.5..1.5));
            sim.set_joint_state(q, qd);
            let obs = sim.true_observation();
            let e_pos = (Vector3::from(obs.ee_pos) - fk_ee(&obs.q)).norm();
            worst_pos[phase] = worst_pos[phase].max(e_pos);
            worst_pos_requested =
                worst_pos_requested.max((Vector3::from(obs.ee_pos) - fk_ee(&q)).norm());

            let h = 1e-6;
            let v_ref = (fk_ee(&[0, 1, 2].map(|k| obs.q[k] + h * obs.qd[k]))
                - fk_ee(&[0, 1, 2].map(|k| obs.q[k] - h * obs.qd[k])))
                / (2.0 * h);
            let e_vel = (Vector3::from(obs.ee_vel) - v_ref).norm() / v_ref.norm().max(1.0);
            if e_vel > worst_vel[phase].0 {
                worst_vel[phase] = (
                    e_vel,
                    format!(
                        "wrist {wrist_q:?} q {:?} qd {:?}: ee_vel {:?}, J q̇ {:?}",
                        obs.q, obs.qd, obs.ee_vel, v_ref
                    ),
                );
            }
        }
    }
    eprintln!(
        "ee_pos vs FK at the held q: max error {:.3e} m fresh, {:.3e} m after a step; vs FK at the \
         requested q {worst_pos_requested:.3e} m",
        worst_pos[0], worst_pos[1]
    );
    for (phase, (e, at)) in ["fresh", "after a step"].iter().zip(&worst_vel) {
        eprintln!("ee_vel vs J q̇ ({phase}): max |Δv| / max(|v|, 1 m/s) = {e:.3e} ({at})");
    }
    let worst_pos = worst_pos[0].max(worst_pos[1]);
    assert!(
        worst_pos <= 1e-6,
        "ee_pos differs from FK of wrist_3_link by {worst_pos:.3e} m (> 1e-6 m)"
    );
    for (phase, (e, at)) in ["fresh", "after a step"].iter().zip(&worst_vel) {
        assert!(
            *e <= 1e-4,
            "ee_vel ({phase}) differs from J(q) q̇ by {e:.3e} × max(|v|, 1 m/s) (> 1e-4): {at}"
        );
    }
}
