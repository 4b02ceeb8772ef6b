//! The simulator with all six joints active (`Ur5Sim::with_joints(…, 6)`), every UR model:
//! the flange's position and orientation against UR's DH table, and the dynamics (gravity,
//! mass matrix, forward dynamics) against Pinocchio's, committed in
//! `hil-sim/tests/data/pinocchio6.json` by `scripts/sim-reference/pinocchio_reference.py`
//! (its header names the versions and the seed); the wrist servo gains follow the rule of the
//! other joints; the servo tracks six goal angles; the rotation vector is UR's.
//!
//! rapier runs in f32: tolerances are what f32 physics reaches (the three-joint tests' own),
//! never widened to make a test pass.

use hil_sim::servo::wrist_velocity_gain;
use hil_sim::sim::{rotation_vector, MAX_JOINTS};
use hil_sim::Ur5Sim;
use nalgebra::{Matrix3, Matrix6, Rotation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use ur5_shared::config::{SimConfig, TaskConfig};
use ur5_shared::kinematics::UrKinematics;
use ur5_shared::UrModel;

use crate::models::dh_pose;

/// The angle (rad) of the rotation between two rotation matrices.
fn angle_between(a: &Matrix3<f64>, b: &Matrix3<f64>) -> f64 {
    let d = a.transpose() * b;
    let c = ((d.trace() - 1.0) / 2.0).clamp(-1.0, 1.0);
    // acos loses precision near 0: use the skew part's norm there.
    let s = Vector3::new(
        d[(2, 1)] - d[(1, 2)],
        d[(0, 2)] - d[(2, 0)],
        d[(1, 0)] - d[(0, 1)],
    )
    .norm()
        / 2.0;
    s.atan2(c)
}

fn six_arm(model: UrModel, physics_dt: f64) -> Ur5Sim {
    let cfg = SimConfig {
        physics_dt,
        substeps: 1,
        ..SimConfig::for_model(model)
    };
    Ur5Sim::with_joints(cfg, physics_dt, 6).unwrap()
}

fn random_q6(rng: &mut ChaCha8Rng, sim: &Ur5Sim) -> [f64; 6] {
    core::array::from_fn(|j| {
        let l = sim.model().joint(j);
        rng.random_range(l.lower.max(-3.1)..l.upper.min(3.1))
    })
}

#[test]
fn six_joint_arms_have_six_degrees_of_freedom_and_merge_no_link() {
    for model in UrModel::ALL {
        let sim = six_arm(model, 1e-3);
        assert_eq!(sim.joints(), 6);
        let m = sim.model();
        assert_eq!(m.n_active, 6);
        assert_eq!(m.rigid_robot(1.0).links.len(), 7, "{model}");
        assert_eq!(
            m.wrist_joints,
            ["wrist_1_joint", "wrist_2_joint", "wrist_3_joint"]
        );
    }
    let err = Ur5Sim::with_joints(SimConfig::default(), 0.1, 4)
        .err()
        .unwrap();
    assert!(err.to_string().contains("3 (wrist locked) or 6"), "{err}");
}

/// Flange position within 1e-6 m (scaled with the arm's size for f32 rounding, as the
/// three-joint check) and orientation within 1e-6 rad of UR's DH table, over random angles of
/// all six joints; the shared kinematics within the same bounds.
#[test]
fn six_joint_flange_pose_is_the_dh_pose() {
    let mut rng = ChaCha8Rng::seed_from_u64(600);
    for model in UrModel::ALL {
        let mut sim = six_arm(model, 1e-3);
        let kin = UrKinematics::new(model, [0.0; 3]);
        let (mut worst_p, mut worst_r, mut worst_kin) = (0.0f64, 0.0f64, 0.0f64);
        for _ in 0..50 {
            let q = random_q6(&mut rng, &sim);
            sim.set_joint_state_all(&q, &[0.0; 6]);
            let (qs, _) = sim.arm_joints();
            let pose = sim.ee_frame_pose();
            let dh = dh_pose(model, &qs);
            let p = pose.translation.vector;
            worst_p = worst_p.max((p - dh.fixed_view::<3, 1>(0, 3)).norm());
            let r = pose.rotation.to_rotation_matrix().into_inner();
            worst_r = worst_r.max(angle_between(&r, &dh.fixed_view::<3, 3>(0, 0).into_owned()));
            let ee = Vector3::from(sim.true_observation().ee_pos);
            worst_kin = worst_kin.max((ee - Vector3::from(kin.ee_point(&qs))).norm());
        }
        eprintln!(
            "{model} (6 joints): |flange − DH| {worst_p:.2e} m, angle {worst_r:.2e} rad, |ee − shared| {worst_kin:.2e} m"
        );
        let tol = 1e-6 * (model.reach() / UrModel::Ur5.reach()).max(1.0);
        assert!(
            worst_p <= tol && worst_kin <= tol,
            "{model}: {worst_p:.3e} m"
        );
        assert!(worst_r <= 1e-6, "{model}: {worst_r:.3e} rad");
    }
}

/// The committed Pinocchio reference (`scripts/sim-reference/pinocchio_reference.py`).
fn reference() -> serde_json::Value {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/pinocchio6.json");
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn vec_of(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

fn six(v: &serde_json::Value) -> [f64; 6] {
    vec_of(v).try_into().unwrap()
}

/// The shared kinematics (f64) gives Pinocchio's flange pose of each URDF to 1e-12, and UR's
/// rotation vector of Pinocchio's flange rotation is the Rodrigues inverse written out here.
#[test]
fn pinocchio_flange_pose_and_rotation_vector() {
    let r = reference();
    for model in UrModel::ALL {
        let samples = r["models"][model.name()]["samples"].as_array().unwrap();
        for s in samples {
            let q = six(&s["q"]);
            let pos = Vector3::from_vec(vec_of(&s["flange_pos"]));
            let rot = Matrix3::from_row_slice(&vec_of(&s["flange_rot"]));
            let dh = dh_pose(model, &q);
            assert!(
                (dh.fixed_view::<3, 1>(0, 3) - pos).norm() < 1e-12,
                "{model}"
            );
            assert!(angle_between(&dh.fixed_view::<3, 3>(0, 0).into_owned(), &rot) < 1e-12);
            // Rodrigues inverse: θ = acos((tr R − 1)/2), axis from the skew part.
            let theta = ((rot.trace() - 1.0) / 2.0).clamp(-1.0, 1.0).acos();
            let axis = Vector3::new(
                rot[(2, 1)] - rot[(1, 2)],
                rot[(0, 2)] - rot[(2, 0)],
                rot[(1, 0)] - rot[(0, 1)],
            ) / (2.0 * theta.sin());
            let want = axis * theta;
            let got = Vector3::from(rotation_vector(&UnitQuaternion::from_rotation_matrix(
                &Rotation3::from_matrix_unchecked(rot),
            )));
            assert!(
                (got - want).norm() < 1e-9,
                "{model}: rotation vector {got} vs {want}"
            );
            assert!(got.norm() <= std::f64::consts::PI + 1e-12);
        }
    }
}

#[test]
fn rotation_vector_is_urs_at_known_rotations() {
    use std::f64::consts::{FRAC_PI_2, PI};
    let rv = |axis: Vector3<f64>, angle: f64| {
        rotation_vector(&UnitQuaternion::from_axis_angle(
            &nalgebra::Unit::new_normalize(axis),
            angle,
        ))
    };
    assert_eq!(rv(Vector3::z(), 0.0), [0.0; 3]);
    let v = rv(Vector3::x(), FRAC_PI_2);
    assert!((Vector3::from(v) - Vector3::new(FRAC_PI_2, 0.0, 0.0)).norm() < 1e-15);
    // Beyond π the same rotation is the shorter one about the opposite axis (angle ≤ π).
    let v = rv(Vector3::y(), 1.5 * PI);
    assert!((Vector3::from(v) - Vector3::new(0.0, -FRAC_PI_2, 0.0)).norm() < 1e-14);
    // UR's documented example: the flange pointing down, p[…, 0, 3.1416, 0] (π about y).
    let v = rv(Vector3::y(), PI);
    assert!(
        (Vector3::from(v).norm() - PI).abs() < 1e-12 && v[1].abs() > PI - 1e-9,
        "{v:?}"
    );
}

/// Gravity torque (the servo's feed-forward) against Pinocchio's g(q), within 1e-4 of the
/// largest |g| (f32).
#[test]
fn six_joint_gravity_matches_pinocchio() {
    let r = reference();
    for model in UrModel::ALL {
        let mut sim = six_arm(model, 1e-3);
        let mut worst = 0.0f64;
        for s in r["models"][model.name()]["samples"].as_array().unwrap() {
            sim.set_joint_state_all(&six(&s["q"]), &[0.0; 6]);
            let g = sim.gravity_torque_all();
            let want = six(&s["gravity"]);
            let scale = want.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            for j in 0..6 {
                worst = worst.max((g[j] - want[j]).abs() / scale);
            }
        }
        eprintln!("{model}: gravity torque, max error {worst:.2e} of the largest");
        assert!(worst < 1e-4, "{model}: {worst:.3e}");
    }
}

/// Forward dynamics at 0.1 ms against Pinocchio's ABA: max |q̈_sim − q̈_ref| below 1 % of the
/// largest |q̈_ref| (the three-joint check's bound).
#[test]
fn six_joint_accelerations_match_pinocchio() {
    let r = reference();
    for model in UrModel::ALL {
        let mut sim = six_arm(model, 1e-4);
        let mut worst = 0.0f64;
        for s in r["models"][model.name()]["samples"].as_array().unwrap() {
            let (q, qd, tau) = (six(&s["q"]), six(&s["qd"]), six(&s["tau"]));
            let a = sim.joint_acceleration_all(&q, &qd, &tau);
            let want = six(&s["qdd"]);
            let scale = want.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            for j in 0..6 {
                worst = worst.max((a[j] - want[j]).abs() / scale);
            }
        }
        eprintln!("{model}: joint accelerations vs Pinocchio, max relative error {worst:.2e}");
        assert!(worst < 0.01, "{model}: {worst:.3e}");
    }
}

/// The mass matrix: from rest, q̈(τ) − q̈(0) = M⁻¹ τ; the simulator's M⁻¹ (column by column,
/// τ = a unit acceleration's worth of torque on one joint) times Pinocchio's M is the identity
/// within 1 %.
#[test]
fn six_joint_mass_matrix_matches_pinocchio() {
    let r = reference();
    for model in UrModel::ALL {
        let mut sim = six_arm(model, 1e-4);
        let mut worst = 0.0f64;
        for s in r["models"][model.name()]["samples"]
            .as_array()
            .unwrap()
            .iter()
            .take(4)
        {
            let q = six(&s["q"]);
            let m = Matrix6::from_row_slice(&vec_of(&s["mass_matrix"]));
            let a0 = sim.joint_acceleration_all(&q, &[0.0; 6], &[0.0; 6]);
            let mut inv = Matrix6::zeros();
            for k in 0..6 {
                // 10 rad/s² on joint k alone: small steps, far above f32 rounding.
                let mut tau = [0.0; 6];
                tau[k] = 10.0 * m[(k, k)];
                let a = sim.joint_acceleration_all(&q, &[0.0; 6], &tau);
                for j in 0..6 {
                    inv[(j, k)] = (a[j] - a0[j]) / tau[k];
                }
            }
            let e = (inv * m - Matrix6::identity()).abs().max();
            worst = worst.max(e);
        }
        eprintln!("{model}: |M_sim⁻¹ M_pinocchio − I| max {worst:.2e}");
        assert!(worst < 0.01, "{model}: {worst:.3e}");
    }
}

/// Each model's wrist gains are 50 /s (the UR5's velocity-loop bandwidth) times the wrist
/// joint's largest inertia, to two significant digits (`wrist_velocity_gain`'s rule).
#[test]
fn every_models_wrist_gains_follow_its_wrist_inertia() {
    let r = reference();
    for model in UrModel::ALL {
        let inertia = vec_of(&r["models"][model.name()]["wrist_inertia"]);
        let gain = wrist_velocity_gain(model);
        for j in 0..3 {
            let exact = 50.0 * inertia[j];
            let unit = 10f64.powf(exact.log10().floor() - 1.0);
            let want = (exact / unit).round() * unit;
            assert!(
                (gain[j] - want).abs() <= 1e-9 * want,
                "{model} wrist {j}: gain {}, the rule gives {want} ({exact:.4})",
                gain[j]
            );
        }
    }
}

/// The servo at six joints: from the model's start pose (wrist at its rest angles) to goals on
/// every joint, within 1 mrad after 3 s, holding the arm stretched out within 1 mrad; the
/// three-joint API on a six-joint arm holds the wrist at its rest angles.
#[test]
fn six_joint_servo_tracks_and_holds_every_joint() {
    for model in UrModel::ALL {
        let task = TaskConfig::for_model(model);
        let mut sim = Ur5Sim::with_joints(SimConfig::for_model(model), task.dt, 6).unwrap();
        let w = sim.model().wrist_q;
        let s = task.start_q;
        let start = [s[0], s[1], s[2], w[0], w[1], w[2]];
        sim.reset_all(&start, task.goal).unwrap();
        let goal = [
            s[0] + 0.3,
            s[1] - 0.2,
            s[2] + 0.2,
            w[0] + 0.5,
            w[1] - 0.5,
            w[2] + 1.0,
        ];
        for _ in 0..30 {
            sim.step_all(&goal);
        }
        let (q, _) = sim.joint_state_all();
        let err = (0..6).map(|j| (q[j] - goal[j]).abs()).fold(0.0, f64::max);
        let tau = sim.max_abs_torque_all();
        eprintln!("{model}: six-joint servo error {err:.2e} rad after 3 s, max |τ| {tau:.1?}");
        assert!(err < 1e-3, "{model}: {err:.3e} rad");
        for j in 0..MAX_JOINTS {
            assert!(tau[j] <= sim.model().joint(j).effort, "{model} joint {j}");
        }
        // Stretched out, wrist at rest: the largest gravity load.
        let stretched = [0.0, 0.0, 0.0, w[0], w[1], w[2]];
        sim.reset_all(&stretched, task.goal).unwrap();
        for _ in 0..20 {
            sim.step_all(&stretched);
        }
        let (q, _) = sim.joint_state_all();
        let sag = (0..6)
            .map(|j| (q[j] - stretched[j]).abs())
            .fold(0.0, f64::max);
        assert!(sag < 1e-3, "{model}: sags {sag:.2e} rad");
        // The three-joint API: the wrist stays at rest.
        sim.reset(task.start_arm_joints(), task.goal).unwrap();
        for _ in 0..10 {
            sim.step([s[0] + 0.2, s[1], s[2]]);
        }
        let (q, _) = sim.arm_joints();
        let wrist_err = (0..3).map(|k| (q[3 + k] - w[k]).abs()).fold(0.0, f64::max);
        assert!(wrist_err < 1e-3, "{model}: wrist moved {wrist_err:.2e} rad");
    }
}

/// A six-joint arm's flange pose on `hil-sim inspect --q=q0,…,q5` is UR's p[x, y, z, rx, ry,
/// rz] of the DH pose (rotation vector from the Rodrigues inverse of the DH rotation).
#[test]
fn inspect_prints_the_six_joint_flange_pose() {
    let q = [0.4, -1.3, 1.2, -1.1, 1.4, 0.7];
    for model in [UrModel::Ur5, UrModel::Ur5e, UrModel::Ur16e] {
        let arg = format!(
            "--q={}",
            q.iter()
                .map(|v| v.to_string())
                .collect::<Vec<_>>()
                .join(",")
        );
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_hil-sim"))
            .args(["inspect", "--model", model.name(), &arg])
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(j["joints"], 6);
        assert_eq!(j["qdd"].as_array().unwrap().len(), 6);
        let p = six(&j["flange_pose"]);
        let dh = dh_pose(model, &q);
        let rot = dh.fixed_view::<3, 3>(0, 0).into_owned();
        let theta = ((rot.trace() - 1.0) / 2.0).clamp(-1.0, 1.0).acos();
        let want_r = Vector3::new(
            rot[(2, 1)] - rot[(1, 2)],
            rot[(0, 2)] - rot[(2, 0)],
            rot[(1, 0)] - rot[(0, 1)],
        ) / (2.0 * theta.sin())
            * theta;
        let got_p = Vector3::new(p[0], p[1], p[2]);
        let got_r = Vector3::new(p[3], p[4], p[5]);
        assert!(
            (got_p - dh.fixed_view::<3, 1>(0, 3)).norm() < 2e-6,
            "{model}: {got_p}"
        );
        assert!(
            (got_r - want_r).norm() < 2e-6,
            "{model}: {got_r} vs {want_r}"
        );
    }
}
